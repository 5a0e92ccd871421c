"""GridTracker: the same as a hand-written filter loop, t-1 is the previous fused frame."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.dst import PerceptionGridFilter
from dstenv.dst.tracker import GridTracker
from dstenv.grid import relative_pose


def _inputs(t, shape=(24, 20)):
    rng = np.random.default_rng(t)
    return (rng.integers(0, 3, shape).astype(np.uint8), rng.integers(0, 4, shape).astype(np.uint8),
            np.array([0.4 * t, 0.1 * t, 0.02 * t]))


def test_tracker_matches_the_plain_loop():
    tracker = GridTracker((24, 20), cell_size=0.5)
    plain = PerceptionGridFilter((24, 20), cell_size=0.5)
    prev_pose, prev_betp = None, None
    for t in range(5):
        sensor, gis, pose = _inputs(t)
        out = tracker.step(sensor, gis, pose, masses=True)
        m = plain.update(sensor, gis, None if prev_pose is None else relative_pose(prev_pose, pose))
        betp = plain.pignistic()
        np.testing.assert_array_equal(out.masses, m)
        np.testing.assert_array_equal(out.betp, betp)
        np.testing.assert_array_equal(out.betp_prev, betp if prev_betp is None else prev_betp)
        prev_pose, prev_betp = pose, betp
    assert tracker.steps == 5
    tracker.reset()
    first = tracker.step(*_inputs(0))
    np.testing.assert_array_equal(first.betp, first.betp_prev)  # no past after a reset
    assert tracker.steps == 1


def test_tracker_rejects_a_bad_pose():
    with pytest.raises(ValueError, match="finite"):
        GridTracker((4, 4)).step(np.zeros((4, 4), np.uint8), np.zeros((4, 4), np.uint8),
                                 np.array([0.0, np.nan, 0.0]))
