"""The residual driver: action 0 is the grid rule driver's action, k the env's k - 1."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import evaluate
import ppo_grid
from residual import RuleResidual, prefer_rule, wrap
from rl_common import make_env, parse_args
from rule_based import GridRuleDriver


def _drive(env, actions_of, seed: int, steps: int):
    obs, _ = env.reset(seed=seed)
    poses, infos = [], []
    for _ in range(steps):
        obs, _, term, trunc, info = env.step(actions_of(obs))
        poses.append(np.array(env.unwrapped.pipeline.world.ego_pose))
        infos.append(info)
        if term or trunc:
            break
    return np.array(poses), infos


def test_rule_action_and_overrides_drive_the_env_as_named(env_flags: list[str]) -> None:
    args = parse_args(ppo_grid.Args, env_flags)
    plain, wrapped = make_env(args), RuleResidual(make_env(args))
    driver = GridRuleDriver()
    plain.reset(seed=5)
    driver.reset(plain, 5)
    assert wrapped.action_space.n == plain.action_space.n + 1
    assert wrapped.get_action_meanings() == ["RULE", *plain.unwrapped.get_action_meanings()]
    # action 0 everywhere: the rule driver's own drive, pose for pose
    ref, _ = _drive(plain, lambda o: driver.act(o, {}), 5, 25)
    got, infos = _drive(wrapped, lambda o: 0, 5, 25)
    np.testing.assert_array_equal(got, ref)
    assert not any(i["override"] for i in infos)
    # action k: the env's action k - 1 (FASTER every step), an override each time
    ref, _ = _drive(plain, lambda o: 2, 6, 25)
    got, infos = _drive(wrapped, lambda o: 3, 6, 25)
    np.testing.assert_array_equal(got, ref)
    assert all(i["override"] for i in infos)
    with pytest.raises(ValueError, match="not in Discrete"):
        wrapped.step(4)
    with pytest.raises(ValueError, match="--residual"):
        wrap(plain, "autopilot")
    from rule_based import TUNED_PARAMS

    tuned = wrap(make_env(args), "grid-tuned")
    assert isinstance(tuned, RuleResidual) and tuned is not plain
    for key, value in TUNED_PARAMS.items():
        assert getattr(tuned.driver, key) == value
    assert wrapped.driver.give_way_line == GridRuleDriver().give_way_line
    tuned.close()
    plain.close()
    wrapped.close()


def test_residual_ppo_starts_as_the_rule_driver_and_reloads(tmp_path,
                                                            env_flags: list[str]) -> None:
    out = tmp_path / "res"
    flags = [*env_flags, "--n-envs", "1", "--vec-env", "dummy", "--n-steps", "32",
             "--batch-size", "32", "--n-epochs", "1", "--total-timesteps", "32",
             "--map-pool", "2", "--verbose", "0", "--residual", "grid",
             "--residual-p-rule", "0.8"]
    args = parse_args(ppo_grid.Args, [*flags, "--out", str(out)])
    env = make_env(args, wrap=lambda e: wrap(e, "grid"))
    model = ppo_grid.build_model(args, env)
    obs, _ = env.reset(seed=1)
    with torch.no_grad():
        tensor, _ = model.policy.obs_to_tensor(obs)
        p = model.policy.get_distribution(tensor).distribution.probs[0].numpy()
    assert p.shape == (4,) and abs(p[0] - 0.8) < 0.03 and np.argmax(p) == 0
    env.close()
    meta = ppo_grid.main([*flags, "--out", str(out)])
    assert meta["args"]["residual"] == "grid" and meta["action_space"] == "Discrete(4)"
    csv = tmp_path / "ep.csv"
    evaluate.main([*env_flags, "--policies", "--episodes", "1", "--checkpoints",
                   str(out / "model.pt"), "--csv", str(csv)])
    assert len(csv.read_text().splitlines()) == 2
    with pytest.raises(ValueError, match="--residual-p-rule"):
        prefer_rule(model, 1.0)
    with pytest.raises(ValueError, match="--residual with --warm-start"):
        ppo_grid.main([*flags, "--warm-start", "grid", "--out", str(tmp_path / "x")])
    assert json.loads((out / "model.json").read_text())["args"]["residual_p_rule"] == 0.8
