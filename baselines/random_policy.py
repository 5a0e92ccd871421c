"""The random policy on the DSTGrid envs: the floor every learned driver must clear.

Each step samples the env's action space uniformly; the space is seeded with the
episode seed, so a seed replays the same episode. Run::

    python baselines/random_policy.py --episodes 20
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym

from rl_common import EnvArgs, EpisodeResult, evaluate_policy, make_env, opt, parse_args
from rl_common import cli, output_file, report_run


@dataclass
class Args(EnvArgs):
    """Run the random policy on a DSTGrid env."""

    episodes: int = opt(10, "episodes, one per seed")
    seed: int = opt(10_000, "first seed (episode k uses seed + k)")
    csv: str = opt("", "write per-episode results to this CSV file")


class RandomPolicy:
    """Uniform samples of the action space, seeded per episode."""

    name = "random"

    def reset(self, env: gym.Env, seed: int) -> None:
        self.space = env.action_space
        self.space.seed(seed)

    def act(self, obs: Any, info: dict[str, Any]) -> Any:
        return self.space.sample()


def run(args: Args) -> tuple[str, list[EpisodeResult]]:
    """Evaluate the random policy; returns its name and the episodes."""
    env = make_env(args)
    try:
        seeds = range(args.seed, args.seed + args.episodes)
        return RandomPolicy.name, evaluate_policy(env, RandomPolicy(), seeds, log=print)
    finally:
        env.close()


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Command-line entry point; returns the summary (:func:`rl_common.summarize`)."""
    args = parse_args(Args, argv)
    output_file(args.csv, "--csv")  # before the episodes
    name, results = run(args)
    return report_run(name, results, args)


if __name__ == "__main__":
    cli(main)
