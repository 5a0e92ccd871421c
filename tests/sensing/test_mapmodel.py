"""The imperfect map behind the GIS grid (dstenv.sensing.mapmodel, MapError.sample)."""

from __future__ import annotations

import numpy as np

from dstenv.grid import GridSpec
from dstenv.sensing import MapError, gis_grid, label_grid
from dstenv.sensing.config import gis_config
from dstenv.sensing.mapmodel import draw_known_map
from dstenv.sim.types import MapClass

from .worlds import agents, rect_map

EXACT = {"offset_std": 0.0, "rotation_std": 0.0, "missing_building_prob": 0.0,
         "extra_building_rate": 0.0, "outline_shift_std": 0.0, "outline_scale_std": 0.0,
         "road_width": "true", "background": "intermediate"}


def _street_map():
    """A 10 m wide road along x (y in -5..5, 2 lanes of 5 m), a building north of it."""
    m = rect_map([(-10.0, 10.0, 8.0, 18.0)], extent=(-20.0, 20.0, -20.0, 20.0), resolution=0.5,
                 fill=MapClass.INTERMEDIATE)
    m.raster[30:50, :] = MapClass.ROAD  # rows 30..49: y in [-5, 5)
    m.streets = [np.array([[-30.0, 0.0], [30.0, 0.0]])]
    m.street_lanes = np.array([2])
    return m


def test_roads_are_drawn_from_lane_count_times_nominal_width():
    m = _street_map()
    cfg = gis_config({**EXACT, "road_width": "lanes", "nominal_lane_width": 3.0})
    known = draw_known_map(m, cfg, np.random.default_rng(0), np.zeros(0, np.int64))
    rows = np.flatnonzero((known == MapClass.ROAD).all(1))
    # 2 lanes x 3 m: the band |y| <= 3 m, cell centres y = -2.75 .. 2.75 -> rows 34..45
    assert rows.min() == 34 and rows.max() == 45
    assert (known[m.raster == MapClass.BUILDING] == MapClass.BUILDING).all()  # no outline error
    assert (m.raster[30:50] == MapClass.ROAD).all()  # the world is untouched


def test_background_none_and_vacuous_source():
    m = _street_map()
    known = draw_known_map(m, gis_config({**EXACT, "background": "none"}),
                           np.random.default_rng(0), np.zeros(0, np.int64))
    assert set(np.unique(known)) == {MapClass.NONE, MapClass.BUILDING, MapClass.ROAD}
    err = MapError.sample(m, {**EXACT, "source": "none"}, np.random.default_rng(0))
    assert err.vacuous
    spec = GridSpec(16, 16, 1.0)
    assert (gis_grid(m, np.zeros(3), spec, err) == MapClass.NONE).all()
    # the labels still come from the world
    assert (label_grid(m, agents(), np.zeros(3), spec) != 255).all()


def test_outline_errors_move_buildings_and_extra_ones_stand_on_open_ground():
    m = _street_map()
    cfg = gis_config({**EXACT, "outline_shift_std": 1.0, "extra_building_rate": 1.0})
    known = draw_known_map(m, cfg, np.random.default_rng(3), np.zeros(0, np.int64))
    truth_b = m.raster == MapClass.BUILDING
    known_b = known == MapClass.BUILDING
    assert not np.array_equal(truth_b, known_b)
    # extra buildings never cover the true road; roads win over shifted outlines
    assert (known[m.raster == MapClass.ROAD] == MapClass.ROAD).all()
    # a dropped building leaves no trace
    gone = draw_known_map(m, gis_config(EXACT), np.random.default_rng(0), np.array([0]))
    assert not (gone == MapClass.BUILDING).any()


def test_default_error_is_drawn_once_per_episode_and_is_deterministic():
    m = _street_map()
    a = MapError.sample(m, None, np.random.default_rng(5))
    b = MapError.sample(m, None, np.random.default_rng(5))
    assert np.array_equal(a.offset, b.offset) and a.rotation == b.rotation
    assert np.array_equal(a.raster, b.raster) and a.raster is not None
    assert 0 < np.hypot(*a.offset) < 5.0 and abs(a.rotation) < 0.1


def test_street_bands_are_the_cells_within_half_a_width_of_the_line():
    """The row-interval painter equals testing every cell's distance to every segment
    (a polyline with short, long, diagonal and degenerate segments)."""
    from dstenv.sensing.mapmodel import _paint_bands

    rng = np.random.default_rng(4)
    lines = [np.cumsum(rng.normal(0, 3, (12, 2)), 0) + 20, np.array([[2.0, 3.0], [2.0, 3.0],
                                                                      [30.0, 3.0], [30.0, 35.0]]),
             np.cumsum(rng.uniform(-1, 1, (40, 2)), 0) + 15]
    halves = np.array([2.3, 1.5, 3.7])
    ptr = np.cumsum([0] + [len(line) for line in lines]).astype(np.int64)
    out = np.zeros((180, 200), np.uint8)
    _paint_bands(out, np.concatenate(lines), ptr, halves, -1.0, -2.0, 0.25, np.uint8(2))
    yc, xc = np.mgrid[0:180, 0:200] * 0.25 + 0.125
    xc, yc = xc - 1.0, yc - 2.0
    ref = np.zeros(out.shape, bool)
    for line, half in zip(lines, halves):
        for (ax, ay), (bx, by) in zip(line[:-1], line[1:]):
            ex, ey = bx - ax, by - ay
            ll = ex * ex + ey * ey
            t = np.zeros_like(xc) if ll == 0 else ((xc - ax) * ex + (yc - ay) * ey) / ll
            t = np.clip(t, 0.0, 1.0)
            ref |= (ax + t * ex - xc) ** 2 + (ay + t * ey - yc) ** 2 <= half * half
    assert ref.sum() > 1000
    assert np.array_equal(out == 2, ref)


def _moved_reference(polys, cfg, rng):
    """Shifted and scaled outlines as numpy expressions on the list of outlines (the
    former implementation; the vertex means summed as ``poly.mean(0)`` sums)."""
    shift_std, scale_std = cfg["outline_shift_std"], cfg["outline_scale_std"]
    z = rng.standard_normal((len(polys), int(shift_std > 0) * 2 + int(scale_std > 0)))
    shift = shift_std * z[:, :2] if shift_std > 0 else np.zeros((len(polys), 2))
    scale = 1.0 + (scale_std * z[:, -1] if scale_std > 0 else np.zeros(len(polys)))
    keep = [k for k in range(len(polys)) if len(polys[k]) >= 3]
    moved = [polys[k].mean(0) + (polys[k] - polys[k].mean(0)) * max(scale[k], 0.5) + shift[k]
             for k in keep]
    ptr = np.cumsum([0] + [len(p) for p in moved]).astype(np.int64)
    return np.concatenate(moved), ptr


def test_moved_outlines_of_the_flat_table_equal_the_per_outline_expressions():
    from dstenv.sensing.mapmodel import _moved_outlines, _outline_table

    m = _street_map()
    rng = np.random.default_rng(2)
    m.buildings = [rng.uniform(-15, 15, (int(rng.integers(2, 9)), 2)) for _ in range(40)]
    table = _outline_table(m)
    assert _outline_table(m) is table  # kept per map
    kept = np.flatnonzero(rng.random(40) < 0.8)
    for std in ((0.7, 0.08), (0.0, 0.1), (0.5, 0.0)):
        cfg = gis_config({**EXACT, "outline_shift_std": std[0], "outline_scale_std": std[1]})
        xy, ptr = _moved_outlines(table, kept, cfg, r1 := np.random.default_rng(9))
        ref_xy, ref_ptr = _moved_reference([m.buildings[k] for k in kept], cfg,
                                           r2 := np.random.default_rng(9))
        assert np.array_equal(ptr, ref_ptr) and np.array_equal(xy, ref_xy)
        assert r1.random() == r2.random()
    assert len(ptr) - 1 < len(kept)  # outlines of 2 vertices are left out


def test_cached_base_gives_the_raster_drawn_in_order():
    """Every draw of a map equals drawing everything in order on a fresh raster: remap,
    shifted outlines, extra buildings, roads last. The first draw does exactly that,
    the second builds the map's cached base (remap + roads) and later ones reuse it
    (buildings, then the road runs again); for both road modes, the cache following
    a change of the gis keys."""
    from dstenv.sensing.mapmodel import _extra_buildings, _paint_bands
    from dstenv.sim.raster import fill_polygons_flat

    m = _street_map()
    m.buildings.append(np.array([[-12.0, -3.0], [-4.0, -3.0], [-4.0, 6.0], [-12.0, 6.0]]))
    for road_width in ("lanes", "true", "lanes"):
        cfg = gis_config({**EXACT, "road_width": road_width, "outline_shift_std": 1.5,
                          "extra_building_rate": 1.0, "nominal_lane_width": 2.5})
        for seed in (1, 2, 3):
            known = draw_known_map(m, cfg, np.random.default_rng(seed), np.zeros(0, np.int64))
            rng = np.random.default_rng(seed)
            ref = m.raster.copy()
            ref[(ref == MapClass.BUILDING) | (ref == MapClass.INTERMEDIATE)] = \
                MapClass.INTERMEDIATE
            if road_width == "lanes":
                ref[ref == MapClass.ROAD] = MapClass.INTERMEDIATE
            xy, ptr = _moved_reference(m.buildings, cfg, rng)
            fill_polygons_flat(ref, xy, ptr, m.origin, m.resolution, MapClass.BUILDING)
            _extra_buildings(ref, m.raster, m.resolution, rng,
                             int(rng.poisson(1.0 * len(m.buildings))))
            if road_width == "lanes":
                _paint_bands(ref, m.streets[0], np.array([0, 2]), np.array([2.5]),
                             m.origin[0], m.origin[1], m.resolution, np.uint8(MapClass.ROAD))
            else:
                ref[m.raster == MapClass.ROAD] = MapClass.ROAD
            # the extra outline crosses the road: roads must win over it
            assert (ref == MapClass.BUILDING).sum() > 300
            assert np.array_equal(known, ref)
