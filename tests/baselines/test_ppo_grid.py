"""PPO baseline: feature extractor, policy choice, tiny training runs, determinism."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import NatureCNN

import ppo_grid
from ppo_grid import Args, GridCNN, build_model, make_vec_env

TINY = ["--n-envs", "2", "--vec-env", "dummy", "--n-steps", "32", "--batch-size", "32",
        "--n-epochs", "1", "--total-timesteps", "64", "--record-actions", "30",
        "--verbose", "0"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Three tiny runs: seed 0 twice, seed 1 once."""
    from conftest import SMALL_CONFIG

    flags = ["--env-config", json.dumps(SMALL_CONFIG), "--max-episode-steps", "30"]
    runs = {}
    for name, seed in (("a", 0), ("b", 0), ("c", 1)):
        out = tmp_path_factory.mktemp(f"ppo_{name}")
        runs[name] = (out, ppo_grid.main([*TINY, *flags, "--seed", str(seed), "--out", str(out)]))
    return runs


def test_grid_cnn_shapes() -> None:
    box = spaces.Box(0.0, 1.0, (5, 84, 84), np.float32)
    net = GridCNN(box, features_dim=64)
    assert net(torch.rand(3, 5, 84, 84)).shape == (3, 64)
    d = spaces.Dict({"grid": spaces.Box(0.0, 1.0, (10, 40, 40), np.float32),
                     "ego": spaces.Box(-1.0, 1.0, (3,), np.float32)})
    net = GridCNN(d, features_dim=32)
    out = net({"grid": torch.rand(2, 10, 40, 40), "ego": torch.rand(2, 3)})
    assert out.shape == (2, 32) and (out >= 0).all()
    # the ego vector reaches the features: changing only it changes the output
    g = torch.rand(1, 10, 40, 40)
    assert not torch.equal(net({"grid": g, "ego": torch.zeros(1, 3)}),
                           net({"grid": g, "ego": torch.ones(1, 3) * 50}))
    with pytest.raises(ValueError, match="GridCNN"):
        GridCNN(spaces.Box(0.0, 1.0, (40, 40), np.float32))


def test_extractor_choice(env_flags: list[str]) -> None:
    from rl_common import parse_args

    args = parse_args(Args, [*env_flags, "--obs", "image", "--extractor", "nature-cnn",
                             "--ego-state", "none", "--n-envs", "1", "--vec-env", "dummy"])
    env = make_vec_env(args)
    try:
        model = build_model(args, env)
        assert isinstance(model.policy.features_extractor, NatureCNN)
        assert model.observation_space.dtype == np.uint8
        args.obs = "pignistic"
        with pytest.raises(ValueError, match="needs --obs image"):
            build_model(args, env)
        args.extractor = "resnet"
        with pytest.raises(ValueError, match="--extractor"):
            build_model(args, env)
    finally:
        env.close()


def test_training_writes_model_and_log(trained: dict) -> None:
    out, meta = trained["a"]
    assert (out / "model.zip").is_file() and (out / "model.json").is_file()
    assert meta["timesteps"] == 64 and meta["args"]["seed"] == 0
    assert meta["command"].startswith("python baselines/ppo_grid.py")
    assert "--total-timesteps 64" in meta["command"]
    rows = (out / "episodes.csv").read_text().splitlines()
    assert rows[0].startswith("timesteps,wall_s,env,return")
    assert len(rows) >= 2  # 64 steps of 30-step episodes finish at least two


def test_same_seed_same_actions_and_weights(trained: dict) -> None:
    from stable_baselines3 import PPO

    (out_a, a), (out_b, b), (_, c) = trained["a"], trained["b"], trained["c"]
    assert len(a["first_actions"]) == 30
    assert a["first_actions"] == b["first_actions"]
    assert a["first_actions"] != c["first_actions"]
    pa = PPO.load(out_a / "model.zip").policy.state_dict()
    pb = PPO.load(out_b / "model.zip").policy.state_dict()
    assert all(torch.equal(pa[k], pb[k]) for k in pa)


@pytest.mark.slow
def test_subprocess_envs_train(tmp_path, env_flags: list[str]) -> None:
    """The default vector env (subprocesses) pickles the env factory and trains."""
    meta = ppo_grid.main([*env_flags, "--n-envs", "2", "--vec-env", "subproc", "--n-steps",
                          "32", "--batch-size", "32", "--n-epochs", "1", "--total-timesteps",
                          "64", "--verbose", "0", "--out", str(tmp_path)])
    assert meta["timesteps"] == 64 and (tmp_path / "model.zip").is_file()
