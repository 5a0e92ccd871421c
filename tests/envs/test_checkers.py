"""Every registered id passes Gymnasium's and stable-baselines3's env checkers, warning-free."""

from __future__ import annotations

import warnings

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import dstenv  # noqa: F401
from dstenv.envs.registration import VARIANTS

from .conftest import SMALL_CITY, SMALL_GRID

SMALL = {**SMALL_CITY, "highway": {"resolution": 0.5}}


@pytest.mark.parametrize("env_id", list(VARIANTS))
def test_gymnasium_check_env(env_id):
    env = gym.make(env_id, config=SMALL, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", list(VARIANTS))
def test_sb3_check_env(env_id):
    env = gym.make(env_id, config=SMALL)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(env, warn=True)
    env.close()


def test_registration_is_idempotent_and_keeps_the_variant():
    from dstenv.envs.registration import register_envs

    register_envs()
    register_envs()
    spec = gym.spec("DSTGrid-Continuous-v0")
    assert isinstance(spec.entry_point, str) and spec.max_episode_steps == 400
    env = gym.make("DSTGrid-Highway-v0", config={"grid": SMALL_GRID})
    # a user config merges over the variant's preset instead of replacing it
    assert env.unwrapped.config["source"] == "highway"
    assert env.observation_space["grid"].shape == (4, 40, 40)


@pytest.mark.parametrize("mode", ["pignistic", "fcn10", "masses"])
def test_gymnasium_check_env_float_modes(mode):
    # stable-baselines3 warns on any 3-D float Box (it wants uint8 images), so only
    # Gymnasium's checker applies to the float modes; "image" is SB3's mode
    env = gym.make("DSTGrid-Highway-v0", config={**SMALL, "observation": {"type": mode}})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(env.unwrapped)
