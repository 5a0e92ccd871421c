"""Tiny stable-baselines3 PPO runs: CnnPolicy on the image mode, MultiInputPolicy on
the RL ids' dict observation, both out of the box."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO

import dstenv  # noqa: F401

from .conftest import SMALL_HIGHWAY


def _ppo(env_id: str, config: dict, steps: int, policy: str = "CnnPolicy") -> PPO:
    torch.set_num_threads(1)  # tiny nets: threads only contend
    env = gym.make(env_id, config=config)
    model = PPO(policy, env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=steps)
    return model


def test_ppo_cnn_policy_runs_on_highway_variant():
    model = _ppo("DSTGrid-Highway-v0", {**SMALL_HIGHWAY, "observation": {"type": "image"}}, 128)
    assert model.num_timesteps == 128
    obs = np.zeros((4, 40, 40), np.uint8)
    action, _ = model.predict(obs, deterministic=True)
    assert 0 <= int(action) < 5


def test_ppo_multi_input_policy_few_hundred_steps_on_occluded_task():
    # the occlusion task at its RL size (84 x 84), default dict observation
    model = _ppo("DSTGrid-Occluded-v0", {}, 320, "MultiInputPolicy")
    assert model.num_timesteps == 320
    obs = model.get_env().reset()
    assert set(obs) == {"grid", "ego", "route"}
    assert model.predict(obs)[0].shape == (1,) and 0 <= int(model.predict(obs)[0][0]) < 3
