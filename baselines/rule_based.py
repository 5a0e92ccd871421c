"""Rule-based reference drivers for the DSTGrid envs, in one readable file.

* ``autopilot`` (default): the world's own autopilot drives the ego, the rule every
  traffic agent follows: route following (pure pursuit), IDM car following, right
  of way at junctions (signals, stop signs, yield) and crosswalks. It reads the
  simulator's ground truth, not the grid, so hidden cross traffic is no surprise
  to it: a privileged reference, not a perception-based one.
* ``constant``: one fixed action every step (default ``2`` = FASTER on the city),
  a grid-blind driver: what ignoring the perception grid costs.

How the autopilot drives: the env takes a world source (``DSTGridEnv(world=...)``);
:class:`AutopilotWorld` wraps the world the env would build and calls its
``step(None)`` (autopilot) whatever action the env passes on, so rewards, info,
episode end and observations are the env's own. Run::

    python baselines/rule_based.py --episodes 20
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any

import gymnasium as gym

import numpy as np
from gymnasium import spaces

from rl_common import EnvArgs, EpisodeResult, env_config, evaluate_policy, make_env, opt
from rl_common import parse_args, report_run

DRIVERS = ("autopilot", "constant")


@dataclass
class Args(EnvArgs):
    """Run a rule-based driver on a DSTGrid env."""

    driver: str = opt("autopilot", "autopilot | constant")
    constant_action: int = opt(2, "the action of the constant driver (city: 0 SLOWER, "
                                  "1 IDLE, 2 FASTER)")
    episodes: int = opt(10, "episodes, one per seed")
    seed: int = opt(10_000, "first seed (episode k uses seed + k)")
    success_distance: float = opt(100.0, "[m] route progress that counts as success")
    csv: str = opt("", "write per-episode results to this CSV file")


class AutopilotWorld:
    """A world source whose ego ignores the actions it is given: its autopilot drives.

    Everything else (map, agents, ego pose, flags, route) is the wrapped world's.

    Args:
        world: a world source (``dstenv.sim.World`` or a highway-env adapter) whose
            ``step(None)`` means autopilot.
    """

    def __init__(self, world: Any) -> None:
        self._inner = world

    def step(self, ego_action: Any = None) -> Any:
        return self._inner.step(None)

    def __getattr__(self, name: str) -> Any:
        if name == "_inner":  # not set yet (e.g. while unpickling)
            raise AttributeError(name)
        return getattr(self._inner, name)


def make_autopilot_env(args: EnvArgs, observation: str | None = None) -> gym.Env:
    """The env of ``args`` (:func:`rl_common.make_env`) driven by its world's autopilot:
    the actions it is given are ignored."""
    from dstenv.pipeline import WORLD_SOURCES

    probe = gym.make(args.env_id, config=env_config(args, observation))
    merged = probe.unwrapped.config  # scenario + variant preset + --env-config
    probe.close()
    world = AutopilotWorld(WORLD_SOURCES[merged["source"]](merged, 0))
    return make_env(args, observation, world=world)


class AutopilotPolicy:
    """The world's autopilot; needs an env from :func:`make_autopilot_env`."""

    name = "rule-based (autopilot)"

    def reset(self, env: gym.Env, seed: int) -> None:
        if not isinstance(env.unwrapped.pipeline.world, AutopilotWorld):
            raise ValueError("AutopilotPolicy: build the env with make_autopilot_env()")
        space = env.action_space  # any valid action will do: the world ignores it
        self._action = (int(space.start) if isinstance(space, spaces.Discrete)
                        else np.zeros(space.shape, space.dtype))

    def act(self, obs: Any, info: dict[str, Any]) -> Any:
        return self._action


class ConstantPolicy:
    """The same action every step (a grid-blind driver)."""

    def __init__(self, action: int) -> None:
        self.action = int(action)
        self.name = f"constant action {self.action}"

    def reset(self, env: gym.Env, seed: int) -> None:
        if not env.action_space.contains(self.action):
            raise ValueError(f"--constant-action {self.action}: not in {env.action_space}")

    def act(self, obs: Any, info: dict[str, Any]) -> int:
        return self.action


def run(args: Args) -> tuple[str, list[EpisodeResult]]:
    """Evaluate the driver of ``args``; returns its name and the episodes."""
    if args.driver not in DRIVERS:
        raise ValueError(f"--driver: expected one of {DRIVERS}, got {args.driver!r}")
    seeds = range(args.seed, args.seed + args.episodes)
    if args.driver == "autopilot":
        policy: Any = AutopilotPolicy()
        env = make_autopilot_env(args)
    else:
        policy = ConstantPolicy(args.constant_action)
        env = make_env(args)
    try:
        results = evaluate_policy(env, policy, seeds, args.success_distance, log=print)
    finally:
        env.close()
    return policy.name, results


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Command-line entry point; returns the summary (:func:`rl_common.summarize`)."""
    args = parse_args(Args, argv)
    name, results = run(args)
    return report_run(name, results, args.csv)


if __name__ == "__main__":
    main(sys.argv[1:])
