"""How the privileged autopilot's episodes end on ``DSTGrid-Occluded-v0`` (issue 17).

Each seed is one episode of ``gym.make("DSTGrid-Occluded-v0", config={"action":
{"type": "autopilot"}}, max_episode_steps=600)`` reset with that seed; it ends in
``collision``, ``off_road``, ``arrived`` or ``timeout`` (the env's
``info["termination_reason"]``) and succeeds as ``info["is_success"]`` says (no
collision, on the road, and arrived or ``info.success_distance`` m of route
progress).

By default the episodes run on the env's world alone (``World(config["world"],
episode_seed)`` with the episode seed the env draws from its seed, stepped by
autopilot with the env's termination and success rules): the perception pipeline does
not touch the world, so the outcome is the env's, ~100x faster. ``--env`` runs them
through the env itself (the check: the same outcomes and steps).

    python docs/autopilot_outcomes.py --seeds 500-599
    python docs/autopilot_outcomes.py --seeds 500-505 --env
"""

from __future__ import annotations

import argparse
import collections
import json
import sys

import gymnasium as gym
import numpy as np

import dstenv  # noqa: F401  (registers the ids)
from dstenv.sim import World

ENV_ID = "DSTGrid-Occluded-v0"
CONFIG = {"action": {"type": "autopilot"}}


def world_episode(config: dict, seed: int, steps: int) -> tuple[str, bool, int]:
    """``(termination_reason, is_success, steps)`` of one episode on the world alone."""
    episode_seed = int(np.random.default_rng(seed).integers(2**31 - 1))  # as the env
    w = World(config["world"], episode_seed)
    progress, reason = 0.0, "timeout"
    k = 0
    for k in range(1, steps + 1):
        before = w.route_progress
        w.step(None)
        progress += w.route_progress - before
        arrived = bool(getattr(w, "route_done", False))
        if w.collision or w.off_road or arrived:
            reason = "collision" if w.collision else "off_road" if w.off_road else "arrived"
            break
    ok = reason in ("arrived", "timeout") and (
        reason == "arrived" or progress >= config["info"]["success_distance"])
    return reason, ok, k


def env_episode(env: gym.Env, seed: int) -> tuple[str, bool, int]:
    """The same through the env."""
    env.reset(seed=seed)
    k, done, info = 0, False, {}
    while not done:
        _, _, te, tr, info = env.step(0)
        k += 1
        done = te or tr
    return info["termination_reason"], bool(info["is_success"]), k


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="500-599", help="first-last (inclusive)")
    ap.add_argument("--steps", type=int, default=600, help="env steps per episode")
    ap.add_argument("--env", action="store_true", help="run through the env (slow)")
    args = ap.parse_args(argv)
    lo, hi = (int(v) for v in args.seeds.split("-"))
    env = gym.make(ENV_ID, config=CONFIG, max_episode_steps=args.steps)
    config = env.unwrapped.config
    assert config["action"]["repeat"] == 1
    tally: collections.Counter = collections.Counter()
    episodes = {}
    for seed in range(lo, hi + 1):
        reason, ok, k = (env_episode(env, seed) if args.env
                         else world_episode(config, seed, args.steps))
        tally[reason] += 1
        tally["success"] += ok
        episodes[seed] = [reason, ok, k]
        print(seed, reason, ok, k, file=sys.stderr, flush=True)
    n = hi - lo + 1
    out = {"command": "python docs/autopilot_outcomes.py " + " ".join(argv or sys.argv[1:]),
           "episodes": n, **{key: tally[key] for key in
                             ("success", "collision", "off_road", "arrived", "timeout")},
           "failed": {s: e[0] for s, e in episodes.items() if not e[1]}}
    print(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
