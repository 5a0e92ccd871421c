"""DAgger warm start: returns, the supervised fit, and a warm-started PPO run."""

from __future__ import annotations

import csv
import json
from contextlib import contextmanager
from typing import Any, Iterator

import numpy as np
import pytest
import torch

import imitation
import ppo_grid
from imitation import DEAD_SPREAD, _fit, discounted_returns
from ppo_grid import Args, build_model, make_vec_env
from conftest import TINY_WARM
from rl_common import parse_args


def test_discounted_returns_stop_at_episode_ends() -> None:
    rewards = np.array([[1.0, 2.0], [1.0, 0.0], [1.0, 4.0]])
    dones = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    g = discounted_returns(rewards, dones, 0.5)
    # env 0: its episode ends after step 1, so step 0 sees only 1 + 0.5 * 1
    np.testing.assert_allclose(g[:, 0], [1.5, 1.0, 1.0])
    # env 1 runs through: 2 + 0.5 * (0 + 0.5 * 4)
    np.testing.assert_allclose(g[:, 1], [3.0, 2.0, 4.0])


@contextmanager
def _model_and_data(env_flags: list[str], n: int) -> Iterator[tuple[Any, dict[str, np.ndarray]]]:
    """A fresh PPO model on a one-env dummy vector env of ``env_flags`` and ``n``
    observations: its vectors uniform in [0, 1], its grid empty (a street with nothing
    on it); the env is closed afterwards."""
    args = parse_args(Args, [*env_flags, "--n-envs", "1", "--vec-env", "dummy"])
    env = make_vec_env(args)
    try:
        space = env.observation_space
        rng = np.random.default_rng(0)
        data = {k: rng.uniform(0, 1, (n, *space[k].shape)).astype(space[k].dtype)
                for k in space.spaces if k != "grid"}
        data["grid"] = np.zeros((n, *space["grid"].shape), np.uint8)
        yield build_model(args, env), data
    finally:
        env.close()


def _pin_first_tanh(model: Any) -> None:
    """Pin every unit of the policy MLP's first tanh layer at +-1 whatever the input
    (what a fit at too high a rate does to it)."""
    with torch.no_grad():
        first = model.policy.mlp_extractor.policy_net[0]
        first.bias.copy_(1e4 * torch.sign(torch.randn_like(first.bias)))


def test_fit_learns_labels_and_returns(env_flags: list[str]) -> None:
    """Labels that follow the ego speed feature, returns that follow it too: the fit
    must reach them on held-out rows (an untrained policy guesses ~1/3)."""
    with _model_and_data(env_flags, 600) as (model, data):
        speed = data["ego"][:, 0]
        data["label"] = np.digitize(speed, [1 / 3, 2 / 3])  # 0, 1, 2 by speed
        returns = (10.0 * speed).astype(np.float32)
        before = _fit(model, data, returns, epochs=0, lr=1e-3, batch=64,
                      rng=np.random.default_rng(0))
        after = _fit(model, data, returns, epochs=30, lr=3e-3, batch=64,
                     rng=np.random.default_rng(0))
    assert before["accuracy"] < 0.6
    assert after["accuracy"] > 0.85
    assert after["value_rmse"] < 0.5 * before["value_rmse"]


def test_fit_reports_a_policy_that_ignores_its_input(env_flags: list[str]) -> None:
    """The failure of a fit at too high a rate (seed 2 of the anchored recipe, 2026-12-06):
    features ~300x their initial size saturate the policy MLP's first tanh layer, so every
    observation gets the same logits; ``logit_spread`` says so, a fresh policy's does not."""
    with _model_and_data(env_flags, 200) as (model, data):
        data["label"] = np.arange(200) % 3
        returns = np.zeros(200, np.float32)
        fresh = _fit(model, data, returns, epochs=0, lr=1e-3, batch=64,
                     rng=np.random.default_rng(0))
        _pin_first_tanh(model)
        saturated = _fit(model, data, returns, epochs=0, lr=1e-3, batch=64,
                         rng=np.random.default_rng(0))
    assert fresh["logit_spread"] > 10 * DEAD_SPREAD
    assert saturated["logit_spread"] < DEAD_SPREAD


@pytest.mark.parametrize("retries", [2, 0])
def test_a_blind_fit_is_undone_and_redone_at_a_tenth_of_the_rate(
        env_flags: list[str], tmp_path, monkeypatch, retries: int) -> None:
    """Round 0's first fit ends blind (its tanh layer pinned, as a fit at too high a rate
    leaves it): the warm start restores the weights from before that fit and refits at a
    tenth of the rate, which round 1 keeps; ``--warm-start-retries 0`` keeps the blind fit."""
    calls: list[float] = []

    def blinding_fit(model: Any, data: Any, returns: Any, epochs: int, lr: float,
                     batch: int, rng: Any) -> dict[str, float]:
        calls.append(lr)
        if len(calls) == 1:
            _pin_first_tanh(model)
            return _fit(model, data, returns, 0, lr, batch, rng)
        return _fit(model, data, returns, epochs, lr, batch, rng)

    monkeypatch.setattr(imitation, "_fit", blinding_fit)
    meta = ppo_grid.main([*env_flags, *TINY_WARM, "--n-epochs", "1", "--total-timesteps", "184",
                          "--warm-start-lr", "1e-3", "--warm-start-retries", str(retries),
                          "--checkpoint-every", "0", "--out", str(tmp_path / "ws")])
    first, second = meta["warm_start"]["rounds"]
    if retries:
        assert calls == pytest.approx([1e-3, 1e-4, 1e-4])
        assert (first["refits"], second["refits"]) == (1, 0)
        assert first["fit_lr"] == second["fit_lr"] == pytest.approx(1e-4)
        assert first["logit_spread"] > 10 * DEAD_SPREAD
    else:
        assert calls == pytest.approx([1e-3, 1e-3]) and first["refits"] == 0
        assert first["logit_spread"] < DEAD_SPREAD


@pytest.mark.parametrize("expert", ["grid", "grid-tuned", "cautious"])
def test_warm_started_run_counts_its_steps(env_flags: list[str], tmp_path, expert: str,
                                           monkeypatch) -> None:
    out = tmp_path / "ws"
    asked = []  # whether PPO's envs still ask the autopilot (only DAgger's teacher needs it)
    learn = ppo_grid.PPO.learn

    def spy(self, *a, **k):
        asked.append(self.env.env_method("get_wrapper_attr", "config")[0]["info"]["autopilot"])
        return learn(self, *a, **k)

    monkeypatch.setattr(ppo_grid.PPO, "learn", spy)
    meta = ppo_grid.main([*env_flags, *TINY_WARM, "--n-epochs", "1", "--total-timesteps", "184",
                          "--warm-start", expert, "--checkpoint-every", "0",
                          "--keep-checkpoints", "--out", str(out)])
    warm = meta["warm_start"]
    assert ("(tuned:" in warm["method"]) == (expert == "grid-tuned")
    assert ("autopilot advice" in warm["method"]) == (expert == "cautious")
    assert asked == [False]
    assert warm["timesteps"] == 120 and [r["expert_share"] for r in warm["rounds"]] == [
        1.0, 0.5]
    assert warm["rounds"][1]["samples"] == 120
    # the rule driver labels its own driving: the policy fitted to it agrees on most
    assert warm["rounds"][0]["accuracy"] >= 0.5
    assert meta["timesteps"] == 64 and meta["env_steps"] == 184
    rows = list(csv.DictReader(open(out / "episodes.csv")))
    phases = [r["phase"] for r in rows]
    assert phases[0] == "dagger0" and "dagger1" in phases and phases[-1] == "ppo"
    steps = [int(r["timesteps"]) for r in rows]
    assert steps == sorted(steps) and steps[-1] <= 184
    assert min(int(r["timesteps"]) for r in rows if r["phase"] == "ppo") > 120
    assert json.loads((out / "model.json").read_text())["env_steps"] == 184
    # the imitation policy alone is kept, as it was before PPO
    before_ppo = json.loads((out / "model_120.json").read_text())
    assert before_ppo["env_steps"] == 120 and before_ppo["timesteps"] == 0
    assert (out / "model_120.pt").is_file()


@pytest.mark.parametrize("flags, match", [
    (["--warm-start", "autopilot"], "--warm-start"),
    (["--warm-start", "grid", "--warm-start-steps", "1"], "--warm-start-steps"),
    (["--warm-start", "grid", "--warm-start-steps", "500"], "--warm-start-steps"),
    (["--warm-start", "grid", "--warm-start-steps", "60", "--warm-start-lr", "0"],
     "--warm-start-lr"),
    (["--warm-start", "grid", "--warm-start-steps", "60", "--warm-start-retries", "-1"],
     "--warm-start-retries"),
])
def test_bad_warm_start_flags(env_flags: list[str], tmp_path, flags: list[str],
                              match: str) -> None:
    with pytest.raises(ValueError, match=match):
        ppo_grid.main([*env_flags, "--n-envs", "2", "--vec-env", "dummy", "--total-timesteps",
                       "100", "--verbose", "0", *flags, "--out", str(tmp_path / "x")])
