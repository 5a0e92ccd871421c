"""Reward terms: hand-computed values."""

from __future__ import annotations

import pytest

from dstenv.envs.rewards import StepOutcome, default_reward_config, reward_terms


def test_cruising_step():
    cfg = default_reward_config()
    t = reward_terms(StepOutcome(progress=0.9, speed=4.5, decel=0.0, collision=False,
                                 off_road=False), cfg)
    assert t["progress"] == pytest.approx(0.09)  # 0.1 / m * 0.9 m
    assert t["speed"] == pytest.approx(0.025)  # 0.05 * 4.5 / 9
    assert t["collision"] == t["off_road"] == t["hard_brake"] == t["arrived"] == 0.0


def test_crash_with_hard_braking():
    cfg = default_reward_config()
    t = reward_terms(StepOutcome(progress=-0.2, speed=20.0, decel=6.0, collision=True,
                                 off_road=True, arrived=False), cfg)
    assert t["progress"] == pytest.approx(-0.02)
    assert t["speed"] == pytest.approx(0.05)  # capped at the target speed
    assert t["collision"] == -10.0 and t["off_road"] == -5.0 and t["hard_brake"] == -0.5
    assert sum(t.values()) == pytest.approx(-0.02 + 0.05 - 15.5)


def test_braking_at_threshold_is_not_hard():
    cfg = default_reward_config()
    t = reward_terms(StepOutcome(0.0, 0.0, decel=2.5, collision=False, off_road=False), cfg)
    assert t["hard_brake"] == 0.0 and t["speed"] == 0.0


def test_slower_meta_action_brakes_comfortably():
    """A SLOWER meta-action never earns the hard-braking penalty (issue 8's finding)."""
    import gymnasium as gym

    import dstenv  # noqa: F401
    from .conftest import SMALL_CITY

    env = gym.make("DSTGrid-v0", config=SMALL_CITY)
    env.reset(seed=4)
    speeds, brakes = [], []
    for action in [2] * 40 + [0] * 30:  # reach the top speed, then slow down twice
        _, _, terminated, truncated, info = env.step(action)
        speeds.append(env.unwrapped.pipeline.world.ego_speed)
        brakes.append(info["rewards"]["hard_brake"])
        if terminated or truncated:
            break
    env.close()
    assert max(speeds) > 6.0 and speeds[-1] < max(speeds) - 3.0  # it did slow down
    assert all(b == 0.0 for b in brakes)
