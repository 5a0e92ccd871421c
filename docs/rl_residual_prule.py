"""How often a residual PPO policy (``ppo_grid.py --residual grid``) would override the
grid rule driver: its action probabilities along drives where the rule driver drives.

Each seed's episode is driven with action 0 (the rule driver's action) throughout;
at every step the checkpoint's softmax is recorded. Printed per checkpoint: steps,
the mean probability of each action, the smallest P(rule) and the share of steps
whose most likely action is not the rule driver's::

    python docs/rl_residual_prule.py --checkpoints runs/res_s0/model_250000.pt \\
        --env-config '{"reward":{"collision":-30,"off_road":-10},"action":{"repeat":3}}' \\
        --max-episode-steps 200 --seed 20000 --episodes 4
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "baselines"))

import evaluate  # noqa: E402
from rl_common import EnvArgs, cli, opt, parse_args  # noqa: E402


@dataclass
class Args(EnvArgs):
    """Action probabilities of residual PPO checkpoints along rule-driver drives."""

    checkpoints: list[str] = opt([], "model.pt files trained with --residual grid")
    seed: int = opt(20_000, "first seed")
    episodes: int = opt(4, "episodes, one per seed")


def main(argv: list[str]) -> list[dict[str, object]]:
    args = parse_args(Args, argv)
    rows = []
    for path in args.checkpoints:
        policy = evaluate.PPOPolicy(path, temperature=1.0)
        if policy.meta["args"].get("residual", "") != "grid":
            raise ValueError(f"{path}: not trained with --residual grid")
        env = policy.make_env(args)
        probs = []
        try:
            for seed in range(args.seed, args.seed + args.episodes):
                obs, _ = env.reset(seed=seed)
                done = False
                while not done:
                    probs.append(policy.probabilities(obs))
                    obs, _, terminated, truncated, _ = env.step(0)
                    done = terminated or truncated
        finally:
            env.close()
        p = np.array(probs)
        row = {"checkpoint": path, "steps": len(p), "mean_p": p.mean(0).round(3).tolist(),
               "min_p_rule": round(float(p[:, 0].min()), 3),
               "share_argmax_not_rule": float((p.argmax(1) != 0).mean())}
        print(row)
        rows.append(row)
    return rows


if __name__ == "__main__":
    cli(main)
