"""gis_grid: exact lookups under translation and rotation, map errors."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.grid import GridSpec
from dstenv.sensing import MapError, gis_grid
from dstenv.sim.types import MapClass, WorldMap

from .worlds import rect_map

SPEC = GridSpec(8, 8, 1.0)  # ego cell (4, 4); cell (i, j) centre x = 4 - i, y = 4 - j
I, J = np.meshgrid(np.arange(8), np.arange(8), indexing="ij")


def _coded_map() -> WorldMap:
    """20 x 20 raster of 1 m cells from (-10, -10) holding arbitrary MapClass codes."""
    raster = np.random.default_rng(0).integers(0, 4, (20, 20)).astype(np.uint8)
    return WorldMap(raster, (-10.0, -10.0), 1.0)


def test_pure_translation():
    # pose (0.5, 0.5, 0): world centre X = 0.5 + 4 - i -> column 14 - i;
    # Y = 0.5 + 4 - j -> row 14 - j
    m = _coded_map()
    g = gis_grid(m, np.array([0.5, 0.5, 0.0]), SPEC)
    np.testing.assert_array_equal(g, m.raster[14 - J, 14 - I])
    # one more metre east: every column index grows by one
    g2 = gis_grid(m, np.array([1.5, 0.5, 0.0]), SPEC)
    np.testing.assert_array_equal(g2, m.raster[14 - J, 15 - I])


def test_ninety_degree_rotation():
    # yaw pi/2: X = 0.5 - y = j - 3.5 -> column 6 + j ; Y = 0.5 + x = 4.5 - i -> row 14 - i
    m = _coded_map()
    g = gis_grid(m, np.array([0.5, 0.5, np.pi / 2]), SPEC)
    np.testing.assert_array_equal(g, m.raster[14 - I, 6 + J])
    # yaw -pi/2: X = 0.5 + y -> column 14 - j ; Y = 0.5 - x = i - 3.5 -> row 6 + i
    g = gis_grid(m, np.array([0.5, 0.5, -np.pi / 2]), SPEC)
    np.testing.assert_array_equal(g, m.raster[6 + I, 14 - J])


def test_outside_the_map_is_none():
    # pose x = 8.5: column 22 - i, beyond the raster (20 columns) for rows i <= 2
    m = _coded_map()
    g = gis_grid(m, np.array([8.5, 0.5, 0.0]), SPEC)
    assert np.all(g[:3] == MapClass.NONE)
    np.testing.assert_array_equal(g[3:], m.raster[14 - J[3:], 22 - I[3:]])


def test_map_error_offset_and_rotation():
    m = _coded_map()
    pose = np.array([0.5, 0.5, np.pi / 2])
    # believed position 1 m further ahead (ego x = world +y here): rows shift by one
    g = gis_grid(m, pose, SPEC, MapError(np.array([1.0, 0.0])))
    np.testing.assert_array_equal(g, m.raster[15 - I, 6 + J])
    # a heading error of pi/2 on top of yaw 0 equals yaw pi/2
    g = gis_grid(m, np.array([0.5, 0.5, 0.0]), SPEC, MapError(np.zeros(2), np.pi / 2))
    np.testing.assert_array_equal(g, gis_grid(m, pose, SPEC))


def test_missing_buildings():
    # two adjacent buildings sharing the wall x = 2; drop the first only
    m = rect_map([(-3.0, 2.0, -2.0, 2.0), (2.0, 6.0, -2.0, 2.0)], extent=(-10.0, 10.0, -10.0, 10.0),
                 resolution=0.5, fill=MapClass.ROAD)
    err = MapError.sample(m, {"missing_building_prob": 1.0}, np.random.default_rng(0))
    assert err.dropped == (0, 1)
    assert not np.any(err.raster == MapClass.BUILDING)
    from dstenv.sensing.gis import remove_buildings

    r = remove_buildings(m, np.array([0]))
    xc = -10.0 + (np.arange(40) + 0.5) * 0.5
    first = (xc < 2.0)[None, :] & (m.raster == MapClass.BUILDING)
    assert np.all(r[first] == MapClass.INTERMEDIATE)
    np.testing.assert_array_equal(r[~first], m.raster[~first])  # the neighbour keeps its cells
    spec = GridSpec(40, 40, 0.5)
    g = gis_grid(m, np.zeros(3), spec, MapError(np.zeros(2), 0.0, r, (0,)))
    n_true = np.count_nonzero(m.raster == MapClass.BUILDING)
    assert np.count_nonzero(g == MapClass.BUILDING) == n_true - first.sum()
    # the true map is untouched
    assert np.count_nonzero(m.raster == MapClass.BUILDING) == 8 * 18


def test_config_dict_draws_with_the_rng():
    m = rect_map([(-3.0, 2.0, -2.0, 2.0)], extent=(-10.0, 10.0, -10.0, 10.0), resolution=0.5)
    cfg = {"offset_std": 0.5, "rotation_std": 0.05}
    a = gis_grid(m, np.zeros(3), SPEC, cfg, np.random.default_rng(3))
    b = gis_grid(m, np.zeros(3), SPEC, cfg, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    e = MapError.sample(m, cfg, np.random.default_rng(3))
    np.testing.assert_array_equal(a, gis_grid(m, np.zeros(3), SPEC, e))
    offs = np.array([MapError.sample(m, cfg, np.random.default_rng(s)).offset for s in range(400)])
    assert abs(offs.std() / 0.5 - 1) < 0.1
    with pytest.raises(ValueError, match="needs an rng"):
        gis_grid(m, np.zeros(3), SPEC, cfg)
    with pytest.raises(ConfigError, match="unknown key 'offset'"):
        gis_grid(m, np.zeros(3), SPEC, {"offset": 1.0}, np.random.default_rng(0))
    with pytest.raises(ValueError, match="polygons"):
        MapError.sample(rect_map([(0, 1, 0, 1)], polygons=False), {"missing_building_prob": 0.5},
                        np.random.default_rng(0))
    # a map with no building at all drops none (a sparse city's seed stopped generation)
    empty = rect_map([], polygons=False)
    assert not MapError.sample(empty, {"missing_building_prob": 0.5},
                               np.random.default_rng(0)).dropped
