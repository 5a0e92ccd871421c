"""Varied city geometry: curved and diagonal streets (the warp), roundabouts, medians."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from dstenv.sim import World, default_config, generate_city
from dstenv.sim.lanes import Control, LaneKind
from dstenv.sim.raster import Surface, lookup, surface_raster
from dstenv.sim.types import MapClass, ObstacleKind
from dstenv.sim.warp import draw_warp

from .clean import clean_world

SMALL = {"blocks_x": 3, "blocks_y": 3, "block_min": 60.0, "block_max": 90.0}


def _city(seed: int, world: dict | None = None, **map_kw):
    cfg = world or default_config()
    cfg["map"].update(SMALL, **map_kw)
    return generate_city(cfg["map"], cfg["traffic"], np.random.default_rng(seed), cfg["clutter"])


def _vehicle_points(wm) -> tuple[np.ndarray, np.ndarray]:
    net = wm.lanes
    lanes = np.flatnonzero(np.isin(net.kind, [LaneKind.ROAD, LaneKind.CONNECTOR]))
    idx = np.concatenate([np.arange(net.start[k], net.start[k] + net.npts[k]) for k in lanes])
    return net.pts[idx], net.hdg[idx]


def _node_angles(wm) -> np.ndarray:
    """Angle deviations from 90 deg [deg] of the street pairs meeting at each junction."""
    ends: dict[tuple[int, int], list[np.ndarray]] = {}
    for line in wm.streets:
        for p, q in ((line[0], line[1]), (line[-1], line[-2])):
            d = (q - p) / np.hypot(*(q - p))
            ends.setdefault(tuple(np.round(p, 3)), []).append(d)
    dev = []
    for ds in ends.values():
        for i in range(len(ds)):
            for j in range(i + 1, len(ds)):
                ang = np.degrees(np.arccos(np.clip(abs(ds[i] @ ds[j]), 0, 1)))
                if ang > 45:  # the crossing pair (not the two halves of one street)
                    dev.append(90.0 - ang)
    return np.array(dev)


def test_warped_lanes_stay_on_road_and_parking_off_the_lanes():
    for seed in (0, 1):
        wm = _city(seed)
        assert wm.meta["warp"] is not None
        pts, _ = _vehicle_points(wm)
        assert (lookup(wm, pts) == MapClass.ROAD).all()
        slots = wm.meta["parking_slots"]
        assert len(slots) > 10
        assert (lookup(wm, slots[:, :2]) == MapClass.INTERMEDIATE).all()
        d = np.hypot(*(slots[:, None, :2] - pts[None, ::4]).transpose(2, 0, 1)).min(1)
        assert d.min() > 1.8  # a lane centre is >= half a lane + the slot's half width away


def test_junction_angles_vary_with_the_seed_and_are_right_angles_in_clean():
    devs = [_node_angles(_city(seed)) for seed in range(3)]
    means = [float(np.mean(np.abs(d))) for d in devs]
    assert min(means) > 0.3 and np.ptp(means) > 0.5  # not 90 deg, and not one value
    # bound: shear (15 deg) plus the bends' slope (atan 0.3 < 17 deg), both axes
    assert max(float(np.abs(d).max()) for d in devs) < 15.0 + 2 * 17.0
    clean = _city(0, clean_world())
    assert clean.meta["warp"] is None and len(clean.meta["roundabouts"]) == 0
    assert np.abs(_node_angles(clean)).max() < 1e-9
    assert not (surface_raster(clean) == Surface.VERGE).any()


def test_surface_of_a_warped_city_is_warped_at_first_read():
    """The drawing-only surface is re-sampled through the map's warp when first read:
    on the raster's grid, buildings where the raster has them, roads only on road."""
    wm = _city(1)
    assert wm.meta["warp"] is not None and "surface" not in wm.meta
    surface = surface_raster(wm)
    assert surface.shape == wm.raster.shape and surface_raster(wm) is surface
    assert np.array_equal(surface == Surface.BUILDING, wm.raster == MapClass.BUILDING)
    road = surface == Surface.ROAD
    assert road.sum() > 10_000 and (wm.raster[road] == MapClass.ROAD).all()
    assert "surface_source" not in wm.meta


def test_warp_inverse_headings_and_size():
    cfg = default_config()["map"]
    warp, size = draw_warp(cfg, (300.0, 200.0), np.random.default_rng(3))
    p = np.random.default_rng(0).uniform(0, 200, (50, 2))
    assert np.allclose(warp.inverse(warp.points(p)), p, atol=1e-9)
    # headings follow the image of a short step
    yaw = np.random.default_rng(1).uniform(-np.pi, np.pi, 50)
    step = warp.points(p + 1e-4 * np.stack([np.cos(yaw), np.sin(yaw)], -1)) - warp.points(p)
    h = np.arctan2(step[:, 1], step[:, 0])
    assert np.allclose(np.angle(np.exp(1j * (warp.headings(p, yaw) - h))), 0, atol=1e-5)
    corners = warp.points(np.array([[0, 0], [300, 0], [0, 200], [300, 200.0]]))
    assert corners.min() >= -1e-9 and (corners.max(0) <= np.array(size) + 1e-9).all()


def _ring_lanes(net, c, r_ring):
    out = []
    for lane in np.flatnonzero(net.kind == LaneKind.CONNECTOR):
        p = net.polyline(lane)
        if np.abs(np.hypot(*(p - c).T) - r_ring).max() < 1.0:
            out.append(lane)
    return out


def test_roundabout_is_a_one_way_ring_that_routes_reach_the_far_exit():
    wm = _city(0, None, roundabout_prob=1.0, lanes_min=2, lanes_max=2, shear_deg=0.0,
               bend_amplitude=0.0, median_prob=0.0)
    net, rounds = wm.lanes, wm.meta["roundabouts"]
    assert len(rounds) >= 1
    x, y, r_out, r_island = rounds[0]
    c = np.array([x, y])
    assert lookup(wm, c) == MapClass.INTERMEDIATE  # the island: raised, non-navigable
    assert lookup(wm, c + [0.0, (r_out + r_island) / 2]) == MapClass.ROAD
    trunks = wm.obstacles.xy[wm.obstacles.kind == ObstacleKind.TREE_TRUNK]
    assert (np.hypot(*(trunks - c).T) < r_island).any()
    ring = _ring_lanes(net, c, r_out - 2.75)
    assert len(ring) == 8  # 4 pieces between the arms + 4 through the yield points
    for lane in ring:  # counter-clockwise: the position turns left of the heading
        p = net.polyline(lane)
        r, d = p[:-1] - c, np.diff(p, axis=0)
        assert (r[:, 0] * d[:, 1] - r[:, 1] * d[:, 0] > 0).all()
    yields = np.unique(net.node[ring])
    assert (net.node_control[yields[yields >= 0]] != Control.NONE).sum() == 4
    # from the east approach, the connectors lead round to the west exit
    near = [k for k in np.flatnonzero(net.kind == LaneKind.ROAD)
            if np.hypot(*(net.polyline(k)[-1] - c)) < r_out + 8 and net.polyline(k)[-1][0] > x
            and np.cos(net.hdg[net.start[k] + net.npts[k] - 2]) < -0.9]
    west = {k for k in np.flatnonzero(net.kind == LaneKind.ROAD)
            if np.hypot(*(net.polyline(k)[0] - c)) < r_out + 8 and net.polyline(k)[0][0] < x
            and np.cos(net.hdg[net.start[k]]) < -0.9}
    assert near and west
    for start in near:
        seen, todo, found = {start}, deque([(start, 0)]), None
        while todo:
            lane, depth = todo.popleft()
            if lane in west:
                found = depth
                break
            for nxt in net.successors(lane):
                if nxt not in seen and (net.kind[nxt] == LaneKind.CONNECTOR or nxt in west):
                    seen.add(nxt)
                    todo.append((nxt, depth + 1))
        assert found is not None and found >= 4  # entry, ring pieces, exit


def test_medians_are_raised_between_opposite_lanes_and_broken_at_junctions():
    wm = _city(2, None, median_prob=1.0, lanes_min=2, lanes_max=2, roundabout_prob=0.0)
    cells = np.argwhere(surface_raster(wm) == Surface.VERGE)
    assert len(cells) > 1000
    assert (wm.raster[cells[:, 0], cells[:, 1]] == MapClass.INTERMEDIATE).all()
    xy = (cells[:, ::-1][:: max(len(cells) // 150, 1)] + 0.5) * wm.resolution
    road = np.flatnonzero(np.repeat(wm.lanes.kind == LaneKind.ROAD, wm.lanes.npts))
    pts, hdg = wm.lanes.pts[road], wm.lanes.hdg[road]
    for p in xy:
        d = np.hypot(*(pts - p).T)
        near = d < 6.0
        assert near.any()
        n = np.stack([-np.sin(hdg[near]), np.cos(hdg[near])], -1)
        side = np.einsum("ij,ij->i", p - pts[near], n)  # > 0: the cell left of the lane
        # every nearby lane has the median on its left: the two directions on both sides
        assert (side > 0).all()
        assert np.cos(hdg[near][:, None] - hdg[near][None, :]).min() < -0.9
    junctions = wm.lanes.node_xy[np.unique(wm.lanes.node[wm.lanes.node >= 0])]
    gap = np.hypot(*(xy[:, None] - junctions[None]).transpose(2, 0, 1)).min(1)
    assert gap.min() > 8.0


def test_same_seed_same_city_and_keys_validated():
    a, b = _city(4), _city(4)
    assert np.array_equal(a.raster, b.raster) and np.array_equal(a.lanes.pts, b.lanes.pts)
    assert np.array_equal(a.obstacles.xy, b.obstacles.xy)
    assert all(np.array_equal(p, q) for p, q in zip(a.buildings, b.buildings))
    assert not np.array_equal(a.lanes.pts[:100], _city(5).lanes.pts[:100])
    from dstenv.config import ConfigError

    with pytest.raises(ConfigError, match=r"world\.map\.bend_amplitude: must be <="):
        World({"map": {"bend_amplitude": 20.0, "bend_wavelength": 100.0}})
    with pytest.raises(ConfigError, match=r"world\.map\.shear_deg: must be in \[0, 30\]"):
        World({"map": {"shear_deg": 45.0}})


def test_batched_polylines_and_polygon_fill_match_one_by_one():
    from dstenv.sim.raster import fill_polygon, fill_polygons

    warp, _ = draw_warp(default_config()["map"], (200.0, 200.0), np.random.default_rng(0))
    polys = [np.array([[0, 0], [10, 0], [10, 23], [0, 0.0]]), np.array([[5, 5], [50, 5.0]])]
    out = warp.polylines(polys, 5.0)
    assert [len(o) for o in out] == [1 + 2 + 5 + 6, 1 + 9]  # pieces of <= 5 m
    assert np.allclose(out[0][[0, 2, 7]], warp.points(np.array([[0, 0], [10, 0], [10, 23.0]])))
    rng = np.random.default_rng(1)
    shapes = [rng.uniform(0, 40, 2) + rng.uniform(0, 15, (k, 2)) for k in (3, 5, 8)]
    one, many = np.zeros((300, 300), np.uint8), np.zeros((300, 300), np.uint8)
    for p in shapes:
        fill_polygon(one, [p], (0.0, 0.0), 0.2, 1)
    fill_polygons(many, shapes, (0.0, 0.0), 0.2, 1)
    assert one.sum() > 100 and np.array_equal(one, many)
