"""Shared pieces of the RL baselines: arguments, wrappers, statistics, atomic files."""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest

from rl_common import (EnvArgs, EpisodeResult, atomic_write_text,
                       env_config, make_env, opt, parse_args, summarize, to_argv)


@dataclass
class _Args:
    n: int = opt(1, "an int")
    rate: float = opt(0.5, "a float")
    name: str = opt("a", "a string")
    flag: bool = opt(True, "a bool")
    xs: list[int] = opt([1], "a list")


def test_parse_args_types_and_round_trip() -> None:
    a = parse_args(_Args, ["--n", "3", "--rate", "0.25", "--no-flag", "--xs", "4", "5"])
    assert a == _Args(n=3, rate=0.25, name="a", flag=False, xs=[4, 5])
    assert to_argv(a) == ["--n", "3", "--rate", "0.25", "--no-flag", "--xs", "4", "5"]
    assert parse_args(_Args, to_argv(a)) == a
    assert to_argv(_Args()) == []
    with pytest.raises(SystemExit):
        parse_args(_Args, ["--unknown", "1"])


def test_env_config_merges_observation_and_rejects_bad_json() -> None:
    args = EnvArgs(env_config='{"grid": {"height": 40}, "observation": {"type": "image"}}')
    speed_only = {"turns": False}  # the baselines choose speed; the route fixes the turns
    assert env_config(args, "pignistic") == {"grid": {"height": 40},
                                             "observation": {"type": "pignistic"},
                                             "action": speed_only}
    assert env_config(EnvArgs()) == {"action": speed_only}
    own = EnvArgs(env_config='{"action": {"max_accel": 2.4}}')
    assert env_config(own) == {"action": {"turns": False, "max_accel": 2.4}}
    assert env_config(EnvArgs(env_config='{"action": {"turns": true}}'))["action"]["turns"]
    with pytest.raises(ValueError, match="--env-config"):
        env_config(EnvArgs(env_config="{grid"))
    with pytest.raises(ValueError, match="JSON object"):
        env_config(EnvArgs(env_config="[1]"))


def test_summarize_hand_computed() -> None:
    res = [EpisodeResult(0, 1.0, 10, True, False, False, 10.0, False),
           EpisodeResult(1, 2.0, 20, False, True, False, 20.0, False),
           EpisodeResult(2, 6.0, 30, False, False, False, 120.0, True)]
    s = summarize(res)
    assert s["success"] == pytest.approx(1 / 3)
    assert s["collision"] == pytest.approx(1 / 3) and s["off_road"] == pytest.approx(1 / 3)
    assert s["return"] == pytest.approx(3.0)
    # sample std of (1, 2, 6) = sqrt(14 / 2); standard error = that / sqrt(3)
    assert s["return_se"] == pytest.approx(math.sqrt(7.0) / math.sqrt(3.0))
    assert s["progress"] == pytest.approx(50.0) and s["length"] == pytest.approx(20.0)
    with pytest.raises(ValueError, match="no episodes"):
        summarize([])


def test_wrappers_report_speed_route_and_progress(small_config: dict) -> None:
    import json

    args = EnvArgs(env_config=json.dumps(small_config))
    env = make_env(args, "pignistic", ego_state="speed+route")
    assert isinstance(env.observation_space, gym.spaces.Dict)
    assert env.observation_space["grid"].shape == (5, 40, 40)
    assert env.observation_space["ego"].shape == (17,)
    obs, info = env.reset(seed=3)
    world = env.unwrapped.pipeline.world
    scale = env.unwrapped.config["world"]["ego"]["max_speed"]
    for _ in range(15):
        obs, _, terminated, truncated, info = env.step(2)
        assert env.observation_space.contains(obs)
        ego = obs["ego"]
        assert ego[0] == pytest.approx(min(info["ego_speed"] / scale, 1.0), abs=1e-6)
        # route points k * 5 m ahead (scaled by 40 m): the chord is at most the arc,
        # and the first one lies ahead of the ego
        dist = np.hypot(ego[1::2], ego[2::2]) * 40.0
        assert np.all(dist <= 5.0 * np.arange(1, 9) + 0.5)
        assert ego[1] > 0.05
        # the progress reward term divided by its weight adds up to the world's odometer
        assert info["route_progress"] == pytest.approx(world.route_progress, abs=1e-6)
        if terminated or truncated:
            break
    assert info["route_progress"] > 0.0
    env.close()
    speed_only = make_env(args, "image", ego_state="speed")
    assert speed_only.observation_space["ego"].shape == (1,)
    speed_only.close()
    with pytest.raises(ValueError, match="ego state"):
        make_env(args, ego_state="route")


def test_atomic_write_leaves_no_temp_file(tmp_path) -> None:
    target = tmp_path / "sub" / "out.txt"
    atomic_write_text(target, "one")
    atomic_write_text(target, "two")
    assert target.read_text() == "two"
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]
