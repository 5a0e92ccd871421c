"""The filter's ego motion with a real INS's step errors (``protocol.odometry_*``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.grid import relative_pose
from dstenv.pipeline import Pipeline
from dstenv.sensing.odometry import Odometry

OFF = {"odometry_along": 0.0, "odometry_drift": 0.0, "odometry_yaw": 0.0}


def _drive(n: int) -> np.ndarray:
    """``(n, 3)`` poses of a gentle left curve at 12 m/s, 0.1 s apart."""
    t = np.arange(n) * 0.1
    yaw = 0.05 * t
    return np.column_stack([np.cumsum(1.2 * np.cos(yaw)), np.cumsum(1.2 * np.sin(yaw)), yaw])


def test_off_is_the_true_pose_itself():
    odo = Odometry(OFF)
    pose = np.array([1.0, 2.0, 0.3])
    assert odo.estimate(pose) is pose


def test_step_errors_have_the_configured_statistics():
    cfg = {"odometry_along": 0.04, "odometry_drift": 0.01, "odometry_yaw": 0.02}
    odo = Odometry(cfg)
    odo.reset(7)
    poses = _drive(4001)
    est = np.stack([odo.estimate(p) for p in poses])
    assert np.array_equal(est[0], poses[0])  # the first pose is taken as it is
    true_steps = np.array([relative_pose(a, b) for a, b in zip(poses[:-1], poses[1:])])
    est_steps = np.array([relative_pose(a, b) for a, b in zip(est[:-1], est[1:])])
    err = est_steps - true_steps
    assert np.std(err[:, 0]) == pytest.approx(0.04, rel=0.08)  # white along the track
    assert np.std(np.diff(err[:, 1])) == pytest.approx(0.01, rel=0.08)  # a random walk across
    assert np.std(err[:, 2]) == pytest.approx(math.radians(0.02), rel=0.08)
    # one seed, one drive; another seed, another
    again = Odometry(cfg)
    again.reset(7)
    assert np.array_equal(np.stack([again.estimate(p) for p in poses]), est)
    again.reset(8)
    assert not np.array_equal(np.stack([again.estimate(p) for p in poses]), est)


def test_pipeline_feeds_the_estimate_to_the_filter_only():
    noisy = {"protocol": {"odometry_along": 0.05, "odometry_drift": 0.02, "odometry_yaw": 0.05},
             "grid": {"height": 64, "width": 64}}
    a = Pipeline({"grid": {"height": 64, "width": 64}})
    b = Pipeline(noisy)
    fa, fb = a.reset(3), b.reset(3)
    assert np.array_equal(fa.pignistic, fb.pignistic)  # one sweep, no motion yet
    for _ in range(15):
        fa, fb = a.step(None), b.step(None)
    assert np.array_equal(fa.ego_pose, fb.ego_pose)
    assert np.array_equal(fa.sensor, fb.sensor) and np.array_equal(fa.labels, fb.labels)
    assert not np.array_equal(fa.pignistic, fb.pignistic)
    # the same seed gives the same drive
    c = Pipeline(noisy)
    c.reset(3)
    for _ in range(15):
        fc = c.step(None)
    assert np.array_equal(fc.pignistic, fb.pignistic)


def test_bad_values_are_named():
    with pytest.raises(ConfigError, match="odometry_along"):
        Pipeline({"protocol": {"odometry_along": -0.1}})
    with pytest.raises(ConfigError, match="odometry_yaw"):
        Pipeline({"protocol": {"odometry_yaw": 90.0}})


def test_replay_feeds_the_filter_the_same_noisy_poses():
    from dstenv.config import build_config
    from dstenv.segment.replay import filter_episode, generation_params, record_episodes
    from dstenv.segment.shardindex import stored_episodes

    cfg = build_config(None, {"protocol": {"odometry_along": 0.05, "odometry_drift": 0.02,
                                           "odometry_yaw": 0.05},
                              "grid": {"height": 64, "width": 64}})
    pipe = Pipeline(cfg)
    frames = [pipe.reset(2)] + [pipe.step(None) for _ in range(12)]
    (ep,) = record_episodes(cfg, {(2, 0): [6, 12]})
    x = filter_episode(ep, generation_params(cfg))
    for k, s in enumerate((6, 12)):
        assert np.array_equal(x[k, :5], frames[s].pignistic)
        assert np.array_equal(x[k, 5:], frames[s].pignistic_prev)
    # stored frames hold the true poses: not re-filterable, and said why
    fr = [{"seed": 2, "episode": 0, "step": s, "file": None, "index": s} for s in range(3)]
    assert stored_episodes(fr, cfg, require_history=True)[0] == []
    assert "odometry" in stored_episodes(fr, cfg, require_history=True)[1]
