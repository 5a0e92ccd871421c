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
        "--n-epochs", "1", "--total-timesteps", "64", "--map-pool", "2", "--verbose", "0"]


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
    from stable_baselines3.common.torch_layers import CombinedExtractor

    from rl_common import parse_args

    args = parse_args(Args, [*env_flags, "--extractor", "combined", "--n-envs", "1",
                             "--vec-env", "dummy"])
    env = make_vec_env(args)
    try:
        model = build_model(args, env)
        assert isinstance(model.policy.features_extractor, CombinedExtractor)
        assert isinstance(model.policy.features_extractor.extractors["grid"], NatureCNN)
        args.extractor = "grid-cnn"
        assert isinstance(build_model(args, env).policy.features_extractor, GridCNN)
        args.extractor = "resnet"
        with pytest.raises(ValueError, match="--extractor"):
            build_model(args, env)
    finally:
        env.close()


def test_training_writes_state_dict_and_log(trained: dict) -> None:
    out, meta = trained["a"]
    assert (out / "model.pt").is_file() and (out / "model.json").is_file()
    assert meta["timesteps"] == 64 and meta["args"]["seed"] == 0
    assert meta["command"].startswith("python baselines/ppo_grid.py")
    assert "--total-timesteps 64" in meta["command"]
    rows = (out / "episodes.csv").read_text().splitlines()
    assert rows[0] == ("timesteps,wall_s,env,return,length,success,collision,off_road,"
                       "progress_m,phase")
    assert len(rows) >= 2  # 64 steps of 30-step episodes finish at least two
    # only tensors inside: loads with weights_only=True
    state = torch.load(out / "model.pt", weights_only=True)
    assert all(isinstance(v, torch.Tensor) for v in state.values())


def test_same_seed_same_weights(trained: dict) -> None:
    (out_a, _), (out_b, _), (out_c, _) = trained["a"], trained["b"], trained["c"]
    pa, pb, pc = (torch.load(o / "model.pt", weights_only=True) for o in (out_a, out_b, out_c))
    assert all(torch.equal(pa[k], pb[k]) for k in pa)
    assert not all(torch.equal(pa[k], pc[k]) for k in pa)


def test_load_rebuilds_the_policy_and_rejects_other_spaces(trained: dict, small_config) -> None:
    import gymnasium as gym

    out, _ = trained["a"]
    env = gym.make("DSTGrid-Occluded-v0", config=small_config)
    model, meta = ppo_grid.load(out / "model.pt", env)
    saved = torch.load(out / "model.pt", weights_only=True)
    assert all(torch.equal(model.policy.state_dict()[k], saved[k]) for k in saved)
    env.close()
    bigger = gym.make("DSTGrid-Occluded-v0", config={**small_config,
                                                     "grid": {"height": 48, "width": 48}})
    msg = r"trained on .*\(4, 40, 40\).* the env gives .*\(4, 48, 48\)"
    with pytest.raises(ValueError, match=msg):
        ppo_grid.load(out / "model.pt", bigger)
    bigger.close()


@pytest.mark.slow
def test_subprocess_envs_train(tmp_path, env_flags: list[str]) -> None:
    """The default vector env (subprocesses) pickles the env factory and trains."""
    meta = ppo_grid.main([*env_flags, "--n-envs", "2", "--vec-env", "subproc", "--n-steps",
                          "32", "--batch-size", "32", "--n-epochs", "1", "--total-timesteps",
                          "64", "--verbose", "0", "--out", str(tmp_path)])
    assert meta["timesteps"] == 64 and (tmp_path / "model.pt").is_file()


def test_norm_reward_scales_the_update_not_the_log(trained: dict, tmp_path) -> None:
    """--norm-reward: same episodes as run "a" (one rollout, same seed), the env's own
    returns in the log, other weights (the update saw scaled rewards); with
    --keep-checkpoints every checkpoint stays beside model.pt."""
    from conftest import SMALL_CONFIG

    out_a, _ = trained["a"]
    flags = ["--env-config", json.dumps(SMALL_CONFIG), "--max-episode-steps", "30"]
    meta = ppo_grid.main([*TINY, *flags, "--seed", "0", "--norm-reward", "--keep-checkpoints",
                          "--checkpoint-every", "32", "--out", str(tmp_path)])
    assert meta["args"]["norm_reward"] is True
    assert (tmp_path / "episodes.csv").read_text().splitlines()[1:] != []
    log_a = [r.split(",")[3:] for r in (out_a / "episodes.csv").read_text().splitlines()]
    log_n = [r.split(",")[3:] for r in (tmp_path / "episodes.csv").read_text().splitlines()]
    assert log_n == log_a  # returns, lengths and outcomes unscaled
    pa = torch.load(out_a / "model.pt", weights_only=True)
    pn = torch.load(tmp_path / "model.pt", weights_only=True)
    assert not all(torch.equal(pa[k], pn[k]) for k in pa)
    # both saved during the one rollout, before its update: the same weights
    k32, k64 = (torch.load(tmp_path / f"model_{n}.pt", weights_only=True) for n in (32, 64))
    assert all(torch.equal(k32[k], k64[k]) for k in k64)
    assert [json.loads((tmp_path / f"model_{n}.json").read_text())["timesteps"]
            for n in (32, 64)] == [32, 64]


def test_a_kept_checkpoint_is_the_end_of_a_run_of_its_whole_rollouts_before(tmp_path) -> None:
    """model_N.pt is saved within the rollout that reaches N, before its update: the end of
    a run of R x (ceil(N / R) - 1) steps (R = 64 here), as --keep-checkpoints says."""
    from conftest import SMALL_CONFIG

    flags = [*TINY, "--env-config", json.dumps(SMALL_CONFIG), "--max-episode-steps", "30",
             "--seed", "0"]
    ppo_grid.main([*flags, "--total-timesteps", "192", "--checkpoint-every", "32",
                   "--keep-checkpoints", "--out", str(tmp_path / "long")])
    ppo_grid.main([*flags, "--out", str(tmp_path / "short")])  # 64 steps
    kept = sorted(int(p.stem.split("_")[1]) for p in (tmp_path / "long").glob("model_*.pt"))
    assert kept == [32, 64, 96, 128, 160, 192]
    k96, k128, end = (torch.load(p, weights_only=True) for p in (
        tmp_path / "long" / "model_96.pt", tmp_path / "long" / "model_128.pt",
        tmp_path / "short" / "model.pt"))
    assert all(torch.equal(k96[k], end[k]) and torch.equal(k128[k], end[k]) for k in end)
    assert json.loads((tmp_path / "long" / "model_96.json").read_text())["timesteps"] == 96


def test_norm_reward_refuses_a_warm_start(tmp_path) -> None:
    with pytest.raises(ValueError, match="--norm-reward with --warm-start"):
        ppo_grid.main([*TINY, "--norm-reward", "--warm-start", "grid", "--out", str(tmp_path)])
