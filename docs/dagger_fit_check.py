"""Why the anchored recipe's seed 2 imitated nothing: its first DAgger fit, replayed
(issue 17; baselines/README.md, "The anchored recipe's third seed fails")::

    python docs/dagger_fit_check.py --seed 2 --lrs 1e-3 3e-4 1e-4 \\
        --out benchmarks/results/rl/dagger-fit-check-s2.json

Builds the recipe's PPO model for ``--seed`` (the same initial weights as
``ppo_grid.py --seed``), lets the tuned rule driver drive round 0 of the warm start
(25,000 labels, as the recipe's first round), then fits a copy of the initial policy
to those labels at each rate with ``imitation._fit`` (six epochs, as the recipe), and
reports on the last 2,500 observations (the fit's held-out rows): the label accuracy,
the features the policy MLP reads (mean of the active ones, max), the share of the
MLP's first tanh layer beyond 0.99, and the logits' spread over observations. About
1 min for the round and 2 min a rate (7 min in all on the 2-core machine).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "baselines"))

from imitation import _fit, _rollout, discounted_returns  # noqa: E402
from ppo_grid import (Args, build_model, make_vec_env, train_config,  # noqa: E402
                      warm_start_steps_per_round)
from rl_common import make_env, parse_args  # noqa: E402
from rule_based import grid_driver  # noqa: E402

#: the anchored recipe's training flags (the main README's command, issue 17)
RECIPE = ["--env-config", '{"reward":{"collision":-100,"off_road":-10},"action":{"repeat":3}}',
          "--max-episode-steps", "200", "--extractor", "route-cnn", "--total-timesteps",
          "400000", "--map-pool", "0", "--learning-rate", "3e-05", "--gamma", "0.98",
          "--warm-start", "grid-tuned", "--warm-start-steps", "100000",
          "--warm-start-epochs", "6", "--vec-env", "dummy"]


def _state(policy: torch.nn.Module, obs: dict[str, torch.Tensor]) -> dict[str, float]:
    """Features, first-tanh saturation and logits' spread of ``policy`` on ``obs``."""
    with torch.no_grad():
        f = policy.extract_features(obs)
        first = torch.tanh(policy.mlp_extractor.policy_net[0](f))
        logits = policy.action_net(policy.mlp_extractor.forward_actor(f))
    return {"features_mean_active": round(float(f[f > 0].mean()), 3),
            "features_max": round(float(f.max()), 3),
            "first_tanh_saturated": round(float((first.abs() > 0.99).float().mean()), 4),
            "logit_spread": float(logits.std(0).mean())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--lrs", type=float, nargs="+", default=[1e-3, 3e-4, 1e-4])
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    torch.set_num_threads(1)
    args = parse_args(Args, [*RECIPE, "--seed", str(a.seed), "--out", "/nonexistent"])
    env = make_vec_env(args)
    try:
        model = build_model(args, env)
        init = {k: v.clone() for k, v in model.policy.state_dict().items()}
        expert = grid_driver(True)
        probe = make_env(args, train_config(args))
        probe.reset(seed=args.seed)
        expert.reset(probe, args.seed)
        probe.close()
        t = time.monotonic()
        data = _rollout(env, model, expert, warm_start_steps_per_round(args), 1.0,
                        np.random.default_rng(args.seed), lambda *_: None)
        returns = discounted_returns(data.pop("rewards"), data.pop("dones"),
                                     model.gamma).reshape(-1)
        round_s = time.monotonic() - t
        held_out = model.policy.obs_to_tensor(
            {k: v[-2500:] for k, v in data.items() if k != "label"})[0]
        out = {"command": "python docs/dagger_fit_check.py --seed "
                          f"{a.seed} --lrs {' '.join(map(str, a.lrs))} --out {a.out}",
               "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               "seed": a.seed, "labels": np.bincount(data["label"], minlength=3).tolist(),
               "round0_s": round(round_s, 1), "initial": _state(model.policy, held_out),
               "fits": {}}
        for lr in a.lrs:
            model.policy.load_state_dict(init)
            stats = _fit(model, data, returns, args.warm_start_epochs, lr, 256,
                         np.random.default_rng(args.seed))
            out["fits"][str(lr)] = {**stats, **_state(model.policy, held_out)}
            print(lr, json.dumps(out["fits"][str(lr)]), flush=True)
    finally:
        env.close()
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
