"""The 3-D LIDAR: exact hits on the road, kerbs, boxes and walls; skew; determinism."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.grid import GridSpec
from dstenv.sensing.lidar3d import SURFACES, Hdl64
from dstenv.sim.types import MapClass, Obstacles

from .worlds import agents, rect_map

H = 1.73
IDEAL = {"range_noise": 0.0, "dropout": 0.0, "intensity_noise": 0.0, "spin_rate": 0.0,
         "min_range": 0.0}


def _lidar(**kw):
    return Hdl64({"model": "hdl64", "hdl64": {**IDEAL, **kw}})


def _sweep(lidar, world, ag=None, pose=(0.0, 0.0, 0.0), seed=0, **kw):
    return lidar.sweep(world, ag if ag is not None else agents(), np.array(pose),
                       np.random.default_rng(seed), **kw)


def test_flat_road_rings_are_exact():
    lidar = _lidar(channels=8, elevation_top=-4.0, elevation_bottom=-18.0, azimuth_step=1.0)
    cloud = _sweep(lidar, rect_map([]))
    assert len(cloud) == 8 * 360  # every beam returns (all within the 40 m map)
    assert np.allclose(cloud.points[:, 2], -H, atol=1e-5)
    el = np.deg2rad(np.linspace(-4.0, -18.0, 8))[cloud.channel]
    assert np.allclose(np.hypot(cloud.points[:, 0], cloud.points[:, 1]), H / np.tan(-el), rtol=1e-5)
    assert set(cloud.surface) == {SURFACES.index("road")}
    assert cloud.points.dtype == np.float32 and cloud.points.shape[1] == 4


def test_car_side_and_roof():
    lidar = _lidar(channels=32, azimuth_step=0.5)
    car = agents((10.0, 0.0, 0.0, 4.0, 2.0, 0.0))  # faces x = 8..12, y = -1..1, 1.5 m tall
    cloud = _sweep(lidar, rect_map([]), car)
    on = cloud.surface == SURFACES.index("agent")
    p = cloud.points[on]
    side = np.abs(p[:, 0] - 8.0) < 1e-4
    assert side.sum() > 20 and np.all((p[side, 2] >= -H - 1e-5) & (p[side, 2] <= 1.5 - H + 1e-5))
    roof = ~side
    assert roof.any() and np.allclose(p[roof, 2], 1.5 - H, atol=1e-5)
    assert np.all((p[roof, 0] >= 8.0) & (p[roof, 0] <= 12.0 + 1e-4))
    # nothing behind the car in its shadow at road level
    ahead = (np.abs(cloud.points[:, 1]) < 0.5) & (cloud.points[:, 0] > 8.0)
    assert np.all(cloud.surface[ahead] == SURFACES.index("agent"))


def test_wall_height_and_kerb():
    world = rect_map([(20.0, 25.0, -5.0, 5.0)])
    world.building_heights[:] = 2.0  # a low wall: the upper channels pass over it
    world.raster[:, (np.arange(world.raster.shape[1]) * 0.1 - 40.0 >= 12.0)
                 & (np.arange(world.raster.shape[1]) * 0.1 - 40.0 < 14.0)] = MapClass.INTERMEDIATE
    lidar = _lidar(channels=64, azimuth_step=1.0)
    cloud = _sweep(lidar, world)
    front = (np.abs(cloud.points[:, 1]) < 0.3) & (cloud.points[:, 0] > 0)
    p, s = cloud.points[front], cloud.surface[front]
    wall = s == SURFACES.index("building")
    assert np.allclose(p[wall, 0], 20.0, atol=1e-4) and p[wall, 2].max() <= 2.0 - H + 1e-5
    assert wall.sum() < (front & (cloud.points[:, 0] > 19)).sum() + 1
    kerb = s == SURFACES.index("kerb")
    assert kerb.any() and np.all((p[kerb, 0] >= 12.0 - 1e-4) & (p[kerb, 0] <= 14.0 + 1e-4))
    top = np.abs(p[kerb, 2] - (0.12 - H)) < 1e-4
    face = np.abs(p[kerb, 0] - 12.0) < 1e-4  # the vertical kerb face
    assert np.all(top | face)


def test_clutter_crown_from_below_and_trunk():
    world = rect_map([])
    # a trunk (0.4 m, 0-2.5 m) under a 10 m crown from 1.8 to 8 m: channels at 0.29 and
    # 0.72 deg rise into the crown from below, higher ones meet its side at x = 5
    world.obstacles = Obstacles(np.array([[10.0, 0.0], [10.0, 0.0]]), np.zeros(2),
                                np.array([0.4, 10.0]), np.array([0.4, 10.0]),
                                np.array([0.0, 1.8]), np.array([2.5, 8.0]),
                                np.array([2, 3], np.uint8))
    lidar = _lidar(channels=64, azimuth_step=0.5)
    cloud = _sweep(lidar, world)
    cl = cloud.surface == SURFACES.index("clutter")
    crown = cl & (cloud.index == 1)
    under = np.abs(cloud.points[crown, 2] - (1.8 - H)) < 1e-4
    side = np.abs(cloud.points[crown, 0] - 5.0) < 1e-3
    assert under.sum() > 2 and side.sum() > 2 and np.all(under | side)
    assert np.all(cloud.points[crown][under, 0] > 5.0)
    trunk = cl & (cloud.index == 0)
    assert trunk.any() and np.allclose(cloud.points[trunk, 0], 9.8, atol=1e-3)


def test_motion_skew_shifts_returns_by_the_ego_motion():
    world = rect_map([(20.0, 30.0, -39.0, 39.0)])
    still = _sweep(_lidar(channels=4, elevation_top=2.0, elevation_bottom=0.0,
                          azimuth_step=1.0), world)
    skew = _sweep(_lidar(channels=4, elevation_top=2.0, elevation_bottom=0.0, azimuth_step=1.0,
                         spin_rate=10.0), world, speed=10.0)

    def at(cloud, az):
        a = np.rad2deg(np.arctan2(cloud.points[:, 1], cloud.points[:, 0]))
        return cloud.points[(np.abs(a - az) < 0.01) & (cloud.channel == 3), 0]

    # the 45 deg column fires 1/80 s before the front one: 0.125 m further back
    assert at(still, 45.0)[0] == pytest.approx(20.0, abs=1e-4)
    assert at(skew, 45.0)[0] == pytest.approx(20.125, abs=1e-4)
    assert at(skew, 0.0)[0] == pytest.approx(20.0, abs=1e-4)


def test_noise_dropout_blind_zone_and_determinism():
    lidar = Hdl64({"model": "hdl64"})
    world, car = rect_map([(20.0, 30.0, -5.0, 5.0)]), agents((8.0, 4.0, 0.3, 4.5, 1.8, 0.0))
    a = _sweep(lidar, world, car, seed=3)
    b = _sweep(lidar, world, car, seed=3)
    c = _sweep(lidar, world, car, seed=4)
    assert np.array_equal(a.points, b.points)
    assert not np.array_equal(a.points[:100], c.points[:100])
    assert 0.9 * 0.95 * lidar.beams * 0.6 < len(a) < 0.95 * lidar.beams + 1000
    assert np.linalg.norm(a.points[:, :3], axis=1).min() >= 2.0  # the blind zone
    assert 0.0 <= a.points[:, 3].min() and a.points[:, 3].max() <= 1.0
    assert lidar.beams == 64 * 2048


def test_noise_and_dropout_have_their_configured_distributions():
    """Range noise ``N(0, range_noise)`` along the beam, dropout of a ``dropout`` share
    of the returns, reflectance noise ``N(0, intensity_noise)``."""
    noisy = _lidar(range_noise=0.05, dropout=0.1, intensity_noise=0.04)
    ideal = _lidar()
    world = rect_map([])  # the flat road: every beam of the lower channels returns
    clean, a = _sweep(ideal, world), _sweep(noisy, world, seed=2)
    dense_a, dense_c = a.dense(), clean.dense()
    both = np.isfinite(dense_a[:, 0]) & np.isfinite(dense_c[:, 0])
    hit = np.isfinite(dense_c[:, 0])
    assert 1 - both.sum() / hit.sum() == pytest.approx(0.1, abs=0.004)
    dr = (np.linalg.norm(dense_a[both, :3], axis=1)
          - np.linalg.norm(dense_c[both, :3], axis=1))
    assert abs(dr.mean()) < 0.002 and dr.std() == pytest.approx(0.05, rel=0.02)
    di = dense_a[both, 3] - dense_c[both, 3]
    inside = (dense_c[both, 3] > 0.15) & (dense_c[both, 3] < 0.85)  # away from the clip
    assert di[inside].std() == pytest.approx(0.04, rel=0.03)


def test_cloud_takes_kittis_road_to_the_grid():
    spec = GridSpec(128, 128, 0.33)
    lidar = _lidar()
    car = agents((10.0, 0.0, 0.0, 4.0, 2.0, 0.0))
    grid = _sweep(lidar, rect_map([]), car).sensor_grid(spec)
    i, j = spec.to_cell(np.array([8.05, 5.0, 16.0]), np.array([0.0, 0.0, 0.0]))
    assert grid[i[0], j[0]] == 2  # the car's face: occupied
    assert grid[i[1], j[1]] == 1  # the road before it: free
    assert grid[i[2], j[2]] == 0  # its shadow at road level: unknown
    assert (grid == 1).mean() > 0.3


def test_bad_model_and_section_are_named():
    with pytest.raises(ConfigError, match="lidar.model"):
        Hdl64({"model": "hdl32"})
    with pytest.raises(ConfigError, match="lidar.hdl64.azimuth_step"):
        Hdl64({"model": "hdl64", "hdl64": {"azimuth_step": 0.0}})


@pytest.mark.parametrize("yaw_rate", [0.0, 0.4])
def test_column_poses_are_the_numpy_formulas_bit_for_bit(yaw_rate):
    import math

    from dstenv.sensing.lidar3d import _column_poses

    lidar = Hdl64({"model": "hdl64", "mount_x": 0.8, "mount_y": -0.3})
    pose, speed, tau = np.array([12.5, -3.25, 2.1]), 7.5, lidar._tau
    ox, oy, world_az, ux, uy = _column_poses(pose, speed, yaw_rate, tau, lidar.azimuth,
                                             lidar.mount)
    yaw = pose[2] + yaw_rate * tau
    if yaw_rate:
        ex = (np.sin(yaw) - math.sin(pose[2])) / yaw_rate
        ey = (math.cos(pose[2]) - np.cos(yaw)) / yaw_rate
    else:
        ex, ey = math.cos(pose[2]) * tau, math.sin(pose[2]) * tau
    cy, sy = np.cos(yaw), np.sin(yaw)
    np.testing.assert_array_equal(ox, pose[0] + speed * ex + cy * 0.8 - sy * -0.3)
    np.testing.assert_array_equal(oy, pose[1] + speed * ey + sy * 0.8 + cy * -0.3)
    np.testing.assert_array_equal(world_az, yaw + lidar.azimuth)
    np.testing.assert_array_equal(ux, np.cos(yaw + lidar.azimuth))
    np.testing.assert_array_equal(uy, np.sin(yaw + lidar.azimuth))


def test_building_table_by_hand():
    from dstenv.sensing.scene3d import building_table
    from dstenv.sim.types import WorldMap

    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    tri = np.array([[10.0, 0.0], [13.0, 0.0], [13.0, 0.0], [10.0, 4.0]])  # a repeated vertex
    wm = WorldMap(raster=np.zeros((4, 4), np.uint8), origin=np.zeros(2), resolution=1.0,
                  buildings=[square, tri], building_heights=np.array([6.0, 9.0]))
    edges, starts, circles, heights = building_table(wm)
    np.testing.assert_array_equal(edges, [[0, 0, 2, 0], [2, 0, 2, 2], [2, 2, 0, 2], [0, 2, 0, 0],
                                          [10, 0, 13, 0], [13, 0, 10, 4], [10, 4, 10, 0]])
    np.testing.assert_array_equal(starts, [0, 4, 7])
    np.testing.assert_allclose(circles[0], [1.0, 1.0, np.sqrt(2)])
    centre = tri.mean(axis=0)  # (11.5, 1.0)
    np.testing.assert_allclose(circles[1], [*centre, np.hypot(*(tri - centre).T).max()])
    np.testing.assert_array_equal(heights, [6.0, 9.0])
    empty = building_table(WorldMap(raster=np.zeros((4, 4), np.uint8), origin=np.zeros(2),
                                     resolution=1.0))
    assert empty[0].shape == (0, 4) and empty[1].tolist() == [0] and empty[2].shape == (0, 3)
