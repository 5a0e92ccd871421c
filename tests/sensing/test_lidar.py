"""Lidar.sweep: exact ranges against walls and rotated boxes, occlusion, noise, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.dst import SensorState
from dstenv.grid import GridSpec
from dstenv.sensing import HIT_BUILDING, HIT_NONE, Lidar
from dstenv.sim.types import Agents

from .worlds import agents, rect_map

WALL = (5.2, 7.0, -20.0, 20.0)  # a building whose face is 5.2 m ahead of the origin
ROOM = [(-10.5, -10.0, -11, 11), (10.0, 10.5, -11, 11),
        (-11, 11, -10.5, -10.0), (-11, 11, 10.0, 10.5)]
NO_AGENTS = Agents.empty()


def _rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


@pytest.mark.parametrize("mode", ["polygons", "raster"])
def test_single_wall_range_and_grid(mode):
    """4 beams (back, right, forward, left), a wall ahead: range 5.2 m; exact grid cells."""
    world = rect_map([WALL], extent=(-20.0, 20.0, -20.0, 20.0))
    lidar = Lidar({"beams": 4, "max_range": 6.0, "buildings": mode})
    sw = lidar.sweep(world, NO_AGENTS, np.zeros(3), _rng())
    np.testing.assert_allclose(sw.angles, [-np.pi, -np.pi / 2, 0.0, np.pi / 2])
    np.testing.assert_allclose(sw.ranges, [6.0, 6.0, 5.2, 6.0], atol=1e-9)
    np.testing.assert_array_equal(sw.hit, [False, False, True, False])
    np.testing.assert_array_equal(sw.hit_id, [HIT_NONE, HIT_NONE, HIT_BUILDING, HIT_NONE])
    np.testing.assert_allclose(sw.points[2], [5.2, 0.0], atol=1e-9)
    assert np.all(np.isnan(sw.points[[0, 1, 3]]))
    # grid 16 x 16 of 1 m, ego cell (8, 8); cell (i, j) centre at x = 8 - i, y = 8 - j
    g = sw.sensor_grid(GridSpec(16, 16, 1.0))
    U, F, O = SensorState.UNKNOWN, SensorState.FREE, SensorState.OCCUPIED
    expected = np.full((16, 16), U, np.uint8)
    expected[4:9, 8] = F  # forward: x = 0 .. 5.2, the wall face is in row 8 - 5.2 + 0.5 -> 3
    expected[3, 8] = O
    expected[8:15, 8] = F  # backward, no return: x = 0 .. -6 -> rows 8 .. 14
    expected[8, 2:15] = F  # left (columns 2 .. 8) and right (8 .. 14), no return
    np.testing.assert_array_equal(g, expected)


def test_ego_pose_and_mount_offset():
    # ego at (10, 3) facing +y; the wall x in [5.2, 7] of the map shifted to y = 3 + 5.2 ahead
    world = rect_map([(-20.0, 40.0, 8.2, 10.0)], extent=(-20.0, 40.0, -20.0, 40.0))
    lidar = Lidar({"beams": 8, "mount_x": 1.5, "mount_y": 0.0})
    sw = lidar.sweep(world, NO_AGENTS, np.array([10.0, 3.0, np.pi / 2]), _rng())
    fwd = 4  # angle 0
    assert sw.angles[fwd] == 0.0
    np.testing.assert_allclose(sw.ranges[fwd], 5.2 - 1.5, atol=1e-9)
    np.testing.assert_allclose(sw.points[fwd], [5.2, 0.0], atol=1e-9)  # ego frame, mount included
    np.testing.assert_array_equal(sw.origin, [1.5, 0.0])
    g = sw.sensor_grid(GridSpec(16, 16, 1.0))
    assert g[3, 8] == SensorState.OCCUPIED and g[7, 8] == SensorState.FREE


def test_ray_versus_rotated_box_exact():
    # box centred 10 m ahead, rotated 45 deg, 4 x 2 m: the forward ray enters at 10 - sqrt(2)
    lidar = Lidar({"beams": 1800})
    world = rect_map([], extent=(-50.0, 50.0, -50.0, 50.0))
    sw = lidar.sweep(world, agents((10.0, 0.0, np.pi / 4, 4.0, 2.0, 0.0)), np.zeros(3), _rng())
    fwd = 900
    assert sw.angles[fwd] == 0.0 and sw.hit_id[fwd] == 0
    assert sw.ranges[fwd] == pytest.approx(10.0 - np.sqrt(2.0), abs=1e-12)


def _slab_range(origin, direction, centre, yaw, length, width):
    """Independent reference: ray / oriented box entry distance by the slab method."""
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, s], [-s, c]])
    o, d = rot @ (origin - centre), rot @ direction
    t_lo, t_hi = 0.0, np.inf
    for k, half in enumerate((length / 2, width / 2)):
        if abs(d[k]) < 1e-15:
            if abs(o[k]) > half:
                return np.inf
            continue
        t1, t2 = sorted(((-half - o[k]) / d[k], (half - o[k]) / d[k]))
        t_lo, t_hi = max(t_lo, t1), min(t_hi, t2)
    return t_lo if t_lo <= t_hi else np.inf


def test_random_rotated_boxes_match_slab_method():
    rng = np.random.default_rng(11)
    lidar = Lidar({"beams": 720, "max_range": 60.0})
    world = rect_map([], extent=(-70.0, 70.0, -70.0, 70.0))
    pose = np.array([1.0, -2.0, 0.4])
    for _ in range(5):
        box = (*rng.uniform(-30, 30, 2), rng.uniform(-np.pi, np.pi),
               rng.uniform(0.3, 6), rng.uniform(0.3, 3), 0.0)
        sw = lidar.sweep(world, agents(box), pose, _rng())
        ref = np.array([_slab_range(pose[:2], np.array([np.cos(pose[2] + a), np.sin(pose[2] + a)]),
                                    np.array(box[:2]), box[2], box[3], box[4]) for a in sw.angles])
        ref_hit = ref <= 60.0
        np.testing.assert_array_equal(sw.hit, ref_hit)
        np.testing.assert_allclose(sw.ranges[ref_hit], ref[ref_hit], atol=1e-9)
        assert np.all(sw.hit_id[ref_hit] == 0)


def test_occlusion_by_building_and_by_agents():
    world = rect_map([WALL], extent=(-30.0, 30.0, -30.0, 30.0))
    lidar = Lidar({"beams": 360})
    fwd = 180
    front = (3.0, 0.0, 0.0, 1.0, 1.0, 0.0)  # in front of the wall: seen, 2.5 m
    behind = (9.0, 0.0, 0.0, 1.0, 1.0, 0.0)  # behind the wall: hidden
    sw = lidar.sweep(world, agents(behind, front), np.zeros(3), _rng())
    assert sw.hit_id[fwd] == 1 and sw.ranges[fwd] == pytest.approx(2.5)
    sw = lidar.sweep(world, agents(behind), np.zeros(3), _rng())
    assert sw.hit_id[fwd] == HIT_BUILDING and not np.any(sw.hit_id == 0)
    # a near agent occludes a farther one
    sw = lidar.sweep(world, agents((4.0, 0.0, 0.0, 1.0, 1.0, 0.0), (2.0, 0.0, 0.0, 1.0, 1.0, 0.0)),
                     np.zeros(3), _rng())
    assert sw.hit_id[fwd] == 1 and sw.ranges[fwd] == pytest.approx(1.5)


@pytest.mark.parametrize("fov,beams,expect_k", [(360.0, 1800, [0, 1799, 1]), (180.0, 180, [0, 1])])
def test_segment_across_the_start_angle(fov, beams, expect_k):
    # 360: a wall straight behind spans beams 1799, 0, 1 (angle -pi); 180: a wall on the
    # right spans angles on both sides of the first beam (-90 deg)
    if fov == 360.0:
        world = rect_map([(-5.5, -5.0, -1.0, 1.0)], extent=(-20.0, 20.0, -20.0, 20.0))
        dist = 5.0
    else:
        world = rect_map([(-1.0, 1.0, -5.5, -5.0)], extent=(-20.0, 20.0, -20.0, 20.0))
        dist = 5.0
    sw = Lidar({"fov": fov, "beams": beams}).sweep(world, NO_AGENTS, np.zeros(3), _rng())
    assert sw.ranges[0] == pytest.approx(dist, abs=1e-9)
    assert np.all(sw.hit[expect_k])
    assert np.all(sw.hit_id[expect_k] == HIT_BUILDING)


def test_narrow_fov_casts_only_its_beams():
    # a wall straight ahead spans ~11 deg; a 0.001 deg fov used to loop over the ~10^4
    # beam indices of the wall's arc before dropping those outside it (a hang at reset)
    world = rect_map([(5.0, 5.5, -0.5, 0.5)], extent=(-20.0, 20.0, -20.0, 20.0))
    car = agents((5.0, 3.0, 0.0, 4.0, 1.0, 0.0))
    for fov in (0.001, 1.0):
        sw = Lidar({"fov": fov, "beams": 3}).sweep(world, car, np.zeros(3), _rng())
        np.testing.assert_allclose(sw.ranges, 5.0, atol=1e-3)
        assert np.all(sw.hit_id == HIT_BUILDING)


def test_raster_and_polygon_modes_agree_in_a_city():
    rects = [(x, x + 7.0, y, y + 5.0) for x in range(-40, 40, 12) for y in range(-40, 40, 11)
             if abs(x + 3) > 6 or abs(y + 2) > 6]
    world = rect_map(rects, extent=(-50.0, 50.0, -50.0, 50.0), resolution=0.1)
    sp = Lidar({"buildings": "polygons"}).sweep(world, NO_AGENTS, np.array([1.0, 3.0, 0.3]), _rng())
    sr = Lidar({"buildings": "raster"}).sweep(world, NO_AGENTS, np.array([1.0, 3.0, 0.3]), _rng())
    both = sp.hit & sr.hit
    assert both.mean() > 0.9
    # the raster is the polygon rounded to 0.1 m cells: at most one cell diagonal apart
    assert np.max(np.abs(sp.ranges[both] - sr.ranges[both])) <= 0.1 * np.sqrt(2) + 1e-9
    assert np.median(np.abs(sp.ranges[both] - sr.ranges[both])) < 0.05
    # "auto" uses the polygons when there are any, else the raster
    raster_only = rect_map(rects, extent=(-50.0, 50.0, -50.0, 50.0), resolution=0.1, polygons=False)
    sa = Lidar().sweep(raster_only, NO_AGENTS, np.array([1.0, 3.0, 0.3]), _rng())
    np.testing.assert_array_equal(sa.ranges, sr.ranges)


def test_noise_and_dropout_statistics():
    world = rect_map(ROOM, extent=(-20.0, 20.0, -20.0, 20.0))
    clean = Lidar({"beams": 3600}).sweep(world, NO_AGENTS, np.zeros(3), _rng())
    assert clean.hit.all() and clean.valid.all()
    sigma, p = 0.05, 0.2
    noisy = Lidar({"beams": 3600, "range_noise": sigma}).sweep(world, NO_AGENTS, np.zeros(3),
                                                               _rng(5))
    err = noisy.ranges - clean.ranges
    n = err.size
    assert abs(err.mean()) < 4 * sigma / np.sqrt(n)
    assert abs(err.std() / sigma - 1) < 0.1
    np.testing.assert_allclose(np.hypot(*noisy.points.T), noisy.ranges)
    drop = Lidar({"beams": 3600, "dropout": p}).sweep(world, NO_AGENTS, np.zeros(3), _rng(6))
    lost = ~drop.valid
    assert abs(lost.mean() - p) < 4 * np.sqrt(p * (1 - p) / n)
    assert np.all(np.isnan(drop.ranges[lost])) and not np.any(drop.hit[lost])
    assert np.all(drop.hit_id[lost] == HIT_NONE)
    np.testing.assert_array_equal(drop.ranges[~lost], clean.ranges[~lost])


def test_same_rng_state_gives_identical_sweeps():
    world = rect_map(ROOM + [WALL], extent=(-20.0, 20.0, -20.0, 20.0))
    lidar = Lidar({"range_noise": 0.03, "dropout": 0.1})
    ag = agents((3.0, 2.0, 0.3, 4.0, 1.8, 5.0))
    a = lidar.sweep(world, ag, np.array([0.5, 0.2, 0.1]), _rng(42))
    b = lidar.sweep(world, ag, np.array([0.5, 0.2, 0.1]), _rng(42))
    c = lidar.sweep(world, ag, np.array([0.5, 0.2, 0.1]), _rng(43))
    for field in ("angles", "ranges", "hit", "hit_id", "points", "valid"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert not np.array_equal(a.valid, c.valid)
    # without noise and dropout the generator is not touched
    rng = _rng(1)
    Lidar().sweep(world, ag, np.zeros(3), rng)
    assert rng.random() == _rng(1).random()


def test_config_is_validated():
    with pytest.raises(ConfigError, match="unknown key 'beam'.*allowed keys: beams"):
        Lidar({"beam": 10})
    with pytest.raises(ConfigError, match="dropout"):
        Lidar({"dropout": 1.5})
    with pytest.raises(ConfigError, match="buildings"):
        Lidar({"buildings": "voxels"})
    with pytest.raises(ValueError, match="pose"):
        Lidar().sweep(rect_map([]), NO_AGENTS, np.zeros(2), _rng())


def test_building_edges_flattened_like_one_polygon_at_a_time():
    """``Lidar._load_polygons`` (all polygons at once) gives the per-polygon edge list:
    each vertex to the next, a repeated closing vertex dropped, boxes per building."""
    wm = rect_map([(1.0, 3.0, 1.0, 2.0), (-5.0, -2.0, 4.0, 9.0)])
    closed = np.array([[10.0, 10.0], [12.0, 10.0], [11.0, 13.0], [10.0, 10.0]])
    wm.buildings = list(wm.buildings) + [closed]
    lidar = Lidar({"beams": 8})
    lidar._load_polygons(wm)
    edges, starts, boxes = [], [0], []
    for poly in wm.buildings:
        poly = np.asarray(poly, np.float64)
        e = np.concatenate([poly, np.roll(poly, -1, axis=0)], axis=1)
        e = e[np.any(e[:, :2] != e[:, 2:], axis=1)]
        edges.append(e)
        starts.append(starts[-1] + len(e))
        boxes.append(np.concatenate([poly.min(0), poly.max(0)]))
    np.testing.assert_array_equal(lidar._edges, np.concatenate(edges))
    np.testing.assert_array_equal(lidar._starts, starts)
    np.testing.assert_array_equal(lidar._boxes, boxes)
    assert starts[-1] - starts[-2] == 3  # the triangle's closing vertex is not an edge


def test_the_edge_cache_does_not_keep_maps_alive():
    import gc
    import weakref

    lidar = Lidar({"beams": 36})
    world = rect_map([WALL], extent=(-30.0, 30.0, -30.0, 30.0))
    first = lidar.sweep(world, NO_AGENTS, np.zeros(3), _rng())
    ref = weakref.ref(world)
    other = rect_map([(5.0, 6.0, -1.0, 1.0)], extent=(-30.0, 30.0, -30.0, 30.0))
    lidar.sweep(other, NO_AGENTS, np.zeros(3), _rng())  # the lidar now holds `other`
    again = lidar.sweep(world, NO_AGENTS, np.zeros(3), _rng())  # from the cache
    np.testing.assert_array_equal(first.ranges, again.ranges)
    lidar.sweep(other, NO_AGENTS, np.zeros(3), _rng())
    del world, first, again
    gc.collect()
    assert ref() is None  # each default map is ~13 MB: 64 of them were kept before
