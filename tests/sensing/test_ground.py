"""Ground removal: exact planes on synthetic clouds, determinism, the real sample."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.kitti.readers import read_velodyne, split_root, velodyne_path
from dstenv.sensing.ground import (
    CloudError,
    classify_points,
    fit_ground_plane,
    ground_heights,
    ground_walk,
)
from dstenv.sensing.polar import polar_coordinates, prepare_points


def _cloud(slope=0.0, seed=0):
    """Velodyne-like rings on a (tilted) road and the near face of a car at x = 10 m.

    Returns the points; the last 600 are the car's, 0.3-1.4 m above the road.
    """
    rng = np.random.default_rng(seed)
    r, a = np.meshgrid(np.arange(3.0, 30.0, 0.5), np.deg2rad(np.arange(0, 360, 0.4)))
    xy = np.column_stack([(r * np.cos(a)).ravel(), (r * np.sin(a)).ravel()])
    shadow = (xy[:, 0] >= 10.0) & (np.abs(xy[:, 1]) <= xy[:, 0] / 10.0)  # hidden by the car
    xy = xy[~shadow]
    ground = np.column_stack([xy, -1.73 + slope * xy[:, 0]])
    car_y = rng.uniform(-1, 1, 600)
    car = np.column_stack([np.full(600, 10.0), car_y,
                           -1.73 + slope * 10.0 + rng.uniform(0.3, 1.4, 600)])
    return np.vstack([ground, car])


def test_plane_recovered_exactly():
    plane = fit_ground_plane(_cloud())
    np.testing.assert_allclose(plane, [0, 0, 1, 1.73], atol=1e-9)


def test_tilted_plane_and_determinism():
    pts = _cloud(slope=0.05)
    plane = fit_ground_plane(pts, {"seed": 3})
    n = np.array([-0.05, 0.0, 1.0]) / np.hypot(0.05, 1.0)
    np.testing.assert_allclose(plane[:3], n, atol=1e-9)
    np.testing.assert_allclose(plane[3], 1.73 / np.hypot(0.05, 1.0), atol=1e-9)
    np.testing.assert_array_equal(plane, fit_ground_plane(pts, {"seed": 3}))


def test_classify_ground_and_obstacles():
    pts = _cloud()
    ground, obstacle, height = classify_points(pts, fit_ground_plane(pts))
    n_ground = len(pts) - 600
    far = np.hypot(pts[:, 0], pts[:, 1]) > 2.7
    assert ground[:n_ground][far[:n_ground]].all() and not obstacle[:n_ground].any()
    car_h = pts[n_ground:, 2] + 1.73
    np.testing.assert_allclose(height[n_ground:], car_h, atol=1e-9)  # the walk kept the road
    assert (obstacle[n_ground:] == (car_h >= 0.30)).all()
    assert not (ground & obstacle).any()


@pytest.mark.parametrize("local", [True, False])
def test_ground_walk_table_gives_the_heights_exactly(local):
    pts = _cloud(slope=0.05)
    plane = fit_ground_plane(pts)
    h, cell, flat = ground_walk(pts, plane, {"local": local})
    np.testing.assert_allclose(h, pts @ plane[:3] + plane[3], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(h - flat[cell], ground_heights(pts, plane, {"local": local}))
    assert cell.dtype == np.int64 and (local or not flat.any())


def test_local_walk_follows_a_rising_verge():
    # flat road for y < 5, a verge rising at 10% beyond (a field beside the road)
    x, y = np.meshgrid(np.arange(-30, 30, 0.25), np.arange(-30, 30, 0.25))
    z = -1.73 + np.where(y > 5, 0.1 * (y - 5), 0.0)
    pts = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    plane = fit_ground_plane(pts)
    h_plane = ground_heights(pts, plane, {"local": False})
    h_local = ground_heights(pts, plane)
    far_verge = pts[:, 1] > 16  # > 1.1 m above the road plane
    assert (h_plane[far_verge] > 1.0).all()
    assert np.abs(h_local[far_verge]).max() < 0.2


def test_prepare_points_float32_copy_and_polar():
    """The road's float32 copy is exact for float32 rows, the offset shifts x and y, and
    the float32 polar pass is within two ulps of the range and 3e-7 rad of atan2 (the
    azimuth of a point on an axis, signed zeros included, is atan2's)."""
    rng = np.random.default_rng(3)
    pts = rng.uniform(-80, 80, (20000, 4)).astype(np.float32)
    pts[:8, :2] = [[0, 0], [3, 0], [-3, 0], [0, 3], [0, -3], [-3, -0.0], [-0.0, -0.0], [1e-30, 5]]
    xyz, (r, a) = prepare_points(pts)
    assert xyz.dtype == r.dtype == a.dtype == np.float32 and xyz.flags.f_contiguous
    assert np.array_equal(xyz, pts[:, :3])
    x, y = pts[:, 0].astype(np.float64), pts[:, 1].astype(np.float64)
    assert np.all(np.abs(r - np.hypot(x, y)) <= 2 * np.spacing(r))  # float32 arithmetic
    assert np.abs(a - np.arctan2(y, x)).max() < 3e-7
    assert np.array_equal(a[:7], np.arctan2(y[:7], x[:7]).astype(np.float32))
    assert np.all(np.abs(a) <= np.float32(np.pi))
    shifted, (r2, _) = prepare_points(pts, offset=(1.5, -2.0))
    assert np.array_equal(shifted[:, 0], (x + 1.5).astype(np.float32))
    assert np.array_equal(shifted[:, 1], (y - 2.0).astype(np.float32))
    # the float64 polar of the public function agrees with the float32 one
    r64, a64 = polar_coordinates(pts[:, :3].astype(np.float64))
    assert np.abs(r64 - r).max() < 1e-4 and np.abs(a64 - a).max() < 3e-7


def test_no_ground_and_unknown_key():
    with pytest.raises(CloudError, match="ground fit: only 0 candidate points"):
        fit_ground_plane(np.array([[5.0, 0.0, 1.0]]))
    with pytest.raises(ConfigError, match="unknown key 'sead'"):
        fit_ground_plane(_cloud(), {"sead": 1})


def test_real_ground_split(real_root):
    pts = read_velodyne(velodyne_path(split_root(real_root), "0003", 0))
    plane = fit_ground_plane(pts)
    assert plane[2] > 0.99 and 1.55 < plane[3] < 1.8  # road ~1.7 m below the sensor
    ground, obstacle, _ = classify_points(pts, plane)
    assert 0.45 < ground.mean() < 0.8 and 0.15 < obstacle.mean() < 0.4
    # the road ahead (5-15 m, within 2 m of the lane centre) is ground
    ahead = (pts[:, 0] > 5) & (pts[:, 0] < 15) & (np.abs(pts[:, 1]) < 2) & (pts[:, 2] < -1.3)
    assert ground[ahead].mean() > 0.98
