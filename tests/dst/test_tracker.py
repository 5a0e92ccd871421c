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


def test_skipped_betp_changes_nothing_that_is_read():
    """Steps with betp=False (fused frames nobody keeps) give the same masses, and the
    next step with BetP (or latest()) the same BetP and t-1, bit for bit."""
    full, lazy = GridTracker((24, 20), cell_size=0.5), GridTracker((24, 20), cell_size=0.5)
    kept = {0, 3, 4, 7}  # 1, 2, 5, 6 skip BetP, as between frames kept at a stride
    for t in range(8):
        want = full.step(*_inputs(t), masses=True)
        out = lazy.step(*_inputs(t), masses=True, betp=t in kept)
        np.testing.assert_array_equal(out.masses, want.masses)
        if t in kept:
            np.testing.assert_array_equal(out.betp, want.betp)
            np.testing.assert_array_equal(out.betp_prev, want.betp_prev, err_msg=f"t={t}")
            got = lazy.latest()
            assert got[0] is out.betp and got[1] is out.betp_prev
        else:
            assert out.betp is None and out.betp_prev is None
    lazy.step(*_inputs(8), betp=False)  # latest() after one skipped step: from the masses
    want = full.step(*_inputs(8))
    betp, prev = lazy.latest()
    np.testing.assert_array_equal(betp, want.betp)
    np.testing.assert_array_equal(prev, want.betp_prev)
    assert lazy.latest()[0] is betp  # computed once
    lazy.step(*_inputs(9), betp=False)
    lazy.step(*_inputs(10), betp=False)
    with pytest.raises(RuntimeError, match="t-1 is gone"):
        lazy.latest()
    lazy.reset()
    with pytest.raises(RuntimeError, match="no fused frame"):
        lazy.latest()
    lazy.step(*_inputs(0), betp=False)
    betp, prev = lazy.latest()
    assert prev is betp  # the first frame: t-1 is t
