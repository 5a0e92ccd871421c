"""OXTS -> poses: the devkit's Mercator numbers, and plausible motion on the real drive."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.kitti.poses import EARTH_RADIUS, lat_to_scale, latlon_to_mercator, oxts_to_trajectory
from dstenv.kitti.readers import read_calib, read_oxts, split_root


def _oxts(rows):
    out = np.zeros((len(rows), 30))
    out[:, : len(rows[0])] = rows
    return out


def test_mercator_hand_values():
    assert lat_to_scale(0.0) == 1.0
    assert lat_to_scale(60.0) == pytest.approx(0.5)
    mx, my = latlon_to_mercator(0.0, 1.0, 1.0)
    assert mx == pytest.approx(EARTH_RADIUS * np.pi / 180)  # 111319.49 m per degree
    assert my == pytest.approx(0.0, abs=1e-6)
    # northward: y grows like er * ln(tan(45 + lat / 2))
    _, my = latlon_to_mercator(10.0, 0.0, 1.0)
    assert my == pytest.approx(EARTH_RADIUS * np.log(np.tan(np.deg2rad(50.0))))


def test_trajectory_east_then_north_with_heading():
    lat0, scale = 49.0, np.cos(np.deg2rad(49.0))
    dlon = np.rad2deg(5.0 / (scale * EARTH_RADIUS))  # 5 m east
    rows = [[lat0, 8.4, 100, 0, 0, 0.0], [lat0, 8.4 + dlon, 100, 0, 0, np.pi / 2]]
    t = oxts_to_trajectory(_oxts(rows))
    np.testing.assert_allclose(t.poses, [[0, 0, 0], [5.0, 0, np.pi / 2]], atol=1e-6)
    assert t.scale == pytest.approx(scale)
    np.testing.assert_allclose(t.latlon_to_world(lat0, 8.4 + dlon), [5.0, 0.0], atol=1e-6)


def test_velodyne_offset_from_imu():
    # Velodyne 1 m ahead of the IMU (Tr_imu_velo translates by -1 along x); heading north
    tr = np.eye(4)
    tr[0, 3] = -1.0
    rows = [[49.0, 8.4, 100, 0, 0, np.pi / 2], [49.0 + 1e-5, 8.4, 100, 0, 0, np.pi / 2]]
    t = oxts_to_trajectory(_oxts(rows), tr)
    np.testing.assert_allclose(t.poses[0], [0, 0, np.pi / 2], atol=1e-9)
    # a Velodyne point 2 m ahead lies 2 m north of the first Velodyne position
    np.testing.assert_allclose(t.to_world(0, [[2.0, 0.0, 0.0]])[0, :2], [0.0, 2.0], atol=1e-9)
    # the IMU origin (1 m behind the Velodyne) lies 1 m south
    np.testing.assert_allclose(t.to_world(0, [[-1.0, 0.0, 0.0]])[0, :2], [0.0, -1.0], atol=1e-9)


def test_real_poses_plausible(real_root):
    split = split_root(real_root)
    oxts = read_oxts(split / "oxts" / "0003.txt")
    calib = read_calib(split / "calib" / "0003.txt")
    t = oxts_to_trajectory(oxts, calib.Tr_imu_velo)
    assert t.poses.shape == (40, 3)
    np.testing.assert_allclose(t.poses[0, :2], 0.0, atol=1e-9)
    step = np.hypot(*np.diff(t.poses[:, :2], axis=0).T) * 10.0  # [m/s] at 10 Hz
    fwd = oxts[:, 8]  # OXTS forward velocity [m/s]
    # position-derived speed jitters with the GPS (about +-1 m/s) but follows vf
    assert np.all(np.abs(step - fwd[1:]) < 1.5)
    # frames are 0.104 s apart on average (not exactly 10 Hz): 4% faster than vf
    assert 1.0 < step.mean() / fwd[1:].mean() < 1.06
    total = np.hypot(*t.poses[-1, :2])
    assert 40.0 < total < 48.0  # 39 frames at about 11.3 m/s
    # heading follows the OXTS yaw (the Velodyne is mounted almost aligned with the IMU)
    np.testing.assert_allclose(t.poses[:, 2], oxts[:, 5], atol=0.01)
    travel = np.arctan2(*np.diff(t.poses[[0, -1], :2], axis=0)[0][::-1])
    assert travel == pytest.approx(t.poses[:, 2].mean(), abs=0.05)
