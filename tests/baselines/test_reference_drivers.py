"""Reference drivers: the random policy and the rule-based ones (autopilot, constant)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import random_policy
import rule_based
from rl_common import EnvArgs
from rule_based import AutopilotWorld, make_autopilot_env


def test_random_policy_runs_and_is_reproducible(env_flags: list[str]) -> None:
    argv = [*env_flags, "--episodes", "2"]
    first = random_policy.main(argv)
    assert first["episodes"] == 2 and 1 <= first["length"] <= 30
    assert 0.0 <= first["collision"] <= 1.0
    assert random_policy.main(argv) == first


def test_autopilot_env_drives_like_the_world_autopilot(small_config: dict) -> None:
    from dstenv.sim import World

    env = make_autopilot_env(EnvArgs(env_config=json.dumps(small_config)))
    _, info = env.reset(seed=5)
    assert isinstance(env.unwrapped.pipeline.world, AutopilotWorld)
    poses = []
    for _ in range(20):
        _, _, terminated, truncated, info = env.step(0)  # SLOWER, ignored
        poses.append(info["ego_pose"])
        if terminated or truncated:
            break
    world = World(env.unwrapped.config["world"], info["seed"])
    for pose in poses:
        world.step(None)
        np.testing.assert_array_equal(world.ego_pose, pose)
    assert info["ego_speed"] > 0.5  # SLOWER would have kept the ego still
    env.close()


def test_rule_based_main(env_flags: list[str]) -> None:
    auto = rule_based.main([*env_flags, "--episodes", "2"])
    assert auto["episodes"] == 2 and auto["progress"] > 0.0
    const = rule_based.main([*env_flags, "--episodes", "1", "--driver", "constant",
                             "--constant-action", "0"])
    assert const["progress"] == pytest.approx(0.0, abs=0.5)  # SLOWER from standstill
    with pytest.raises(ValueError, match="--constant-action 7"):
        rule_based.main([*env_flags, "--episodes", "1", "--driver", "constant",
                         "--constant-action", "7"])
    with pytest.raises(ValueError, match="--driver"):
        rule_based.main([*env_flags, "--driver", "pilot"])
