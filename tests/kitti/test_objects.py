"""Boxes camera -> Velodyne, world positions and the two moving rules."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.kitti.objects import Boxes, boxes_in_velodyne, moving_flags
from dstenv.kitti.readers import Labels, read_calib
from dstenv.kitti.sequence import KittiSequence

from .conftest import FIXTURES, PARKED, moving_centre


def _labels(location, rotation_y, hwl=(1.5, 1.8, 4.0)):
    n = len(location)
    return Labels(
        frame=np.arange(n), track=np.zeros(n, np.int64), type=np.zeros(n, np.int64),
        bbox=np.zeros((n, 4)), hwl=np.tile(hwl, (n, 1)), location=np.asarray(location, float),
        rotation_y=np.asarray(rotation_y, float),
    )


def test_box_centre_and_yaw_hand_computed():
    calib = read_calib(FIXTURES / "calib_colons.txt")
    # bottom centre (2, 1.73, 10) in the camera; h = 1.5 -> centre (2, 0.98, 10)
    # Velodyne = R^T (p - t) with t = (0, -0.08, -0.27): (10.27, -2, -1.06)
    b = boxes_in_velodyne(_labels([[2.0, 1.73, 10.0]] * 3, [0.0, -np.pi / 2, np.pi / 4]), calib)
    np.testing.assert_allclose(b.centre[0], [10.27, -2.0, -1.06], atol=1e-12)
    # ry about camera y (down) -> yaw = -ry - pi/2 with these axes
    np.testing.assert_allclose(b.yaw, [-np.pi / 2, 0.0, -3 * np.pi / 4], atol=1e-12)
    np.testing.assert_allclose([b.length[0], b.width[0], b.height[0]], [4.0, 1.8, 1.5])


def test_corners_of_rotated_box():
    b = Boxes(frame=np.zeros(1, np.int64), track=np.zeros(1, np.int64), type=np.zeros(1, np.int64),
              centre=np.array([[10.0, 0.0, 0.0]]), length=np.array([4.0]), width=np.array([2.0]),
              height=np.array([1.5]), yaw=np.array([np.pi / 2]))
    np.testing.assert_allclose(b.corners()[0], [[9, 2], [9, -2], [11, -2], [11, 2]], atol=1e-12)


def _track(positions):
    n = len(positions)
    b = Boxes(frame=np.arange(n), track=np.zeros(n, np.int64), type=np.zeros(n, np.int64),
              centre=np.zeros((n, 3)), length=np.ones(n), width=np.ones(n), height=np.ones(n),
              yaw=np.zeros(n))
    return b, np.asarray(positions, float)


def test_paper_rule_flickers_on_jitter_smoothed_does_not():
    rng = np.random.default_rng(0)
    # a parked car seen through pose noise: +-6 cm jumps, one of 12 cm
    parked = np.cumsum(rng.normal(0, 0.01, (20, 2)), axis=0)
    parked[10:] += [0.12, 0.0]
    b, p = _track(parked)
    assert moving_flags(b, p, "paper")[10]  # the 12 cm jump is "moving" under the paper rule
    assert not moving_flags(b, p, "smoothed").any()
    # 0.5 m per frame (5 m/s) is moving under both rules
    b, p = _track(np.stack([np.arange(20) * 0.5, np.zeros(20)], 1))
    assert moving_flags(b, p, "paper").all() and moving_flags(b, p, "smoothed").all()


def test_single_frame_track_is_static_and_bad_rule():
    b, p = _track([[0.0, 0.0]])
    assert not moving_flags(b, p, "paper")[0] and not moving_flags(b, p, "smoothed")[0]
    with pytest.raises(ValueError, match="unknown moving rule 'fast'"):
        moving_flags(b, p, "fast")


def test_synthetic_world_positions(tiny_root):
    seq = KittiSequence(tiny_root, "0001")
    for k in range(6):
        sel = seq.boxes.frame == k
        world = seq.world_xy[sel]
        np.testing.assert_allclose(world[seq.boxes.track[sel] == 0][0], moving_centre(k), atol=1e-6)
        np.testing.assert_allclose(world[seq.boxes.track[sel] == 1][0], PARKED, atol=1e-6)
    for rule in ("paper", "smoothed"):
        mv = seq.moving(rule)
        assert mv[seq.boxes.track == 0].all() and not mv[seq.boxes.track == 1].any()


def test_real_known_tracks(real_root):
    """Tracks 0 and 1 overtake on the right at ~15 m/s; tracks 2 and 3 are parked."""
    seq = KittiSequence(real_root, "0003")
    smooth, paper = seq.moving("smoothed"), seq.moving("paper")
    tr = seq.boxes.track
    assert smooth[(tr == 0) | (tr == 1)].all() and paper[(tr == 0) | (tr == 1)].all()
    assert not smooth[(tr == 2) | (tr == 3)].any()
    # pose noise: the single-step paper rule calls the parked cars moving at least once
    assert paper[(tr == 2) | (tr == 3)].sum() >= 1
    step = np.hypot(*np.diff(seq.world_xy[tr == 2], axis=0).T)
    assert step.max() > 0.10 and np.median(step) < 0.07
    speed0 = np.hypot(*np.diff(seq.world_xy[tr == 0], axis=0).T).mean() * 10
    assert 13.0 < speed0 < 17.0
    # boxes sit on the road surface: centres about 1.73 - h/2 below the Velodyne
    cars = seq.boxes.select(tr == 0)
    np.testing.assert_allclose(cars.centre[:, 2], -1.73 + cars.height / 2, atol=0.3)
