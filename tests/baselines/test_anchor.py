"""The KL anchor: PPO's entropy term becomes -KL(policy || the warm-started policy)."""

from __future__ import annotations

import csv
import json

import pytest
import torch
from stable_baselines3.common.utils import obs_as_tensor

import ppo_grid
from conftest import TINY_WARM
from anchor import anchor_to, kl_to_anchor
from ppo_grid import Args, build_model, make_vec_env
from rl_common import parse_args


@pytest.fixture
def model_and_obs(env_flags: list[str]):
    args = parse_args(Args, [*env_flags, "--n-envs", "2", "--vec-env", "dummy"])
    env = make_vec_env(args)
    try:
        model = build_model(args, env)
        obs = obs_as_tensor(env.reset(), "cpu")
    finally:
        env.close()
    return model, obs


def test_kl_is_zero_at_the_anchor_and_pulls_back(model_and_obs) -> None:
    model, obs = model_and_obs
    policy = model.policy
    keys = set(policy.state_dict())
    anchor = anchor_to(policy)
    assert set(policy.state_dict()) == keys  # the checkpoint does not carry the anchor
    actions = torch.zeros(2, dtype=torch.long)
    _, _, ent = policy.evaluate_actions(obs, actions)
    assert torch.allclose(ent, torch.zeros(2), atol=1e-6)
    with torch.no_grad():  # move the policy away: the reported "entropy" is -KL
        policy.action_net.bias += torch.tensor([2.0, -1.0, 0.0])
    _, log_prob, ent = policy.evaluate_actions(obs, actions)
    p = policy.get_distribution(obs).distribution.probs
    q = anchor.get_distribution(obs).distribution.probs
    manual = (p * (p.log() - q.log())).sum(-1)
    assert (manual > 0.05).all()
    torch.testing.assert_close(-ent, manual)
    assert torch.equal(-ent, kl_to_anchor(policy, anchor, obs))  # the same as a 2nd pass
    torch.testing.assert_close(log_prob, p[:, 0].log())
    # PPO's entropy loss, -mean(entropy) = mean(KL), minimised: back to the anchor
    opt = torch.optim.Adam(policy.action_net.parameters(), lr=0.05)
    for _ in range(200):
        opt.zero_grad()
        loss = -policy.evaluate_actions(obs, actions)[2].mean()
        loss.backward()
        opt.step()
    assert kl_to_anchor(policy, anchor, obs).max() < 0.01 * manual.min()
    assert all(not prm.requires_grad for prm in anchor.parameters())


def test_anchored_run_logs_the_kl(env_flags: list[str], tmp_path) -> None:
    out = tmp_path / "anchored"
    meta = ppo_grid.main([*env_flags, *TINY_WARM, "--n-epochs", "2", "--total-timesteps", "312",
                          "--anchor", "--ent-coef", "0.5", "--learning-rate", "1e-3",
                          "--out", str(out)])
    assert meta["args"]["anchor"] is True and meta["env_steps"] == 312
    rows = list(csv.DictReader(open(out / "progress.csv")))
    kl = [float(r["train/entropy_loss"]) for r in rows if r.get("train/entropy_loss")]
    # three updates, two logged (SB3 logs an update at the next rollout): KL > 0, small
    assert len(kl) == 2 and all(0 <= k < 0.5 for k in kl) and min(kl) > 0
    assert json.loads((out / "model.json").read_text())["args"]["ent_coef"] == 0.5


@pytest.mark.parametrize("flags, message", [
    (["--anchor", "--ent-coef", "0.5"], "--anchor needs --warm-start"),
    (["--anchor", "--warm-start", "grid", "--ent-coef", "0", "--warm-start-steps", "16"],
     r"--anchor needs --ent-coef > 0 \(the KL's weight\), got 0"),
])
def test_anchor_needs_a_warm_start_and_a_weight(env_flags: list[str], tmp_path,
                                                flags: list[str], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ppo_grid.main([*env_flags, "--total-timesteps", "100", "--verbose", "0", *flags,
                       "--out", str(tmp_path / "x")])
    assert not (tmp_path / "x").exists()
