"""``dstenv bench env``: environment steps per second against highway-env.

Measures, in one process, ``env.step`` throughput of

* ``DSTGrid-v0`` at the paper's 256 x 256 x 0.33 m grid,
* ``DSTGrid-RL-v0`` at the RL size (84 x 84 x 1.0 m),
* ``DSTGrid-Highway-v0`` (highway-env's intersection driving our pipeline), and
* the reference: highway-env ``intersection-v2`` (``-v1`` if absent) at 10 Hz
  simulation and policy frequency (one grid per 0.1 s, like ours) with an
  ``OccupancyGrid`` observation of the same extent and cell size as the 256 x 256
  grid (no occlusion, no evidential fusion), in two variants of its observation
  features (:data:`REFERENCE_FEATURES`): ``presence, vx, vy`` (vehicles only) and
  ``presence, on_road`` + ``vx, vy`` (``on_road`` rasterises the lanes into every
  grid, which dominates highway-env's step at this size),

and reports each as a ratio to the ``presence, vx, vy`` reference, so the figures
travel across machines. Actions are random (seeded); resets are not timed (a
terminated episode is reset outside the timer) unless ``resets=True``
(:func:`time_env`), as in the goal row of ``dstenv bench data``.
:func:`time_resets` times ``DSTGrid-RL-v0`` resets apart: with a fresh map per
episode and with a map pool (``world.map.pool``, maps generated before the timer).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

__all__ = ["REFERENCE_FEATURES", "run", "time_env", "time_resets", "highway_reference"]

#: highway-env OccupancyGrid feature sets of the reference (name -> features)
REFERENCE_FEATURES: dict[str, list[str]] = {
    "presence,vx,vy": ["presence", "vx", "vy"],
    "presence,on_road,vx,vy": ["presence", "on_road", "vx", "vy"],
}


def time_env(env: Any, steps: int, action: Any = None, seed: int = 0,
             resets: bool = False) -> float:
    """Steps per second of ``env.step`` over ``steps`` steps.

    Args:
        action: a fixed action, or ``None`` for random actions (``action_space``
            seeded with ``seed``).
        resets: also time the resets of terminated or truncated episodes.
    """
    env.action_space.seed(seed)
    pick = (lambda: env.action_space.sample()) if action is None else (lambda: action)
    env.reset(seed=seed)
    for _ in range(5):  # warm-up: numba dispatch, caches
        _, _, term, trunc, _ = env.step(pick())
        if term or trunc:
            env.reset()
    elapsed = 0.0
    for _ in range(steps):
        t0 = time.perf_counter()
        _, _, term, trunc, _ = env.step(pick())
        if term or trunc:
            if not resets:
                elapsed += time.perf_counter() - t0
                t0 = None
            env.reset()
        if t0 is not None:
            elapsed += time.perf_counter() - t0
    return steps / elapsed


def time_resets(env: Any, resets: int, pool: int = 0) -> float:
    """Mean wall time [ms] of ``env.reset(seed=k)``; with ``pool`` > 0, seeds that
    cover every pool map run first, untimed (the maps exist, as after warm-up)."""
    if pool > 0:
        seen: set[int] = set()
        k = 10_000
        while len(seen) < pool and k < 10_000 + 50 * pool:
            env.reset(seed=k)
            seen.add(env.unwrapped.pipeline.world.map_index)
            k += 1
    else:
        env.reset(seed=10_000)
    t0 = time.perf_counter()
    for k in range(resets):
        env.reset(seed=k)
    return 1000.0 * (time.perf_counter() - t0) / resets


def highway_reference(spec_hw: tuple[int, int], cell: float,
                      features: str = "presence,vx,vy") -> tuple[str, Any]:
    """highway-env's intersection with an OccupancyGrid of our grid's extent: ``(id, env)``."""
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the ids)

    env_id = "intersection-v2" if "intersection-v2" in gym.registry else "intersection-v1"
    h, w = spec_hw
    half_x, half_y = h * cell / 2, w * cell / 2
    env = gym.make(env_id, config={
        "simulation_frequency": 10,
        "policy_frequency": 10,
        "observation": {
            "type": "OccupancyGrid",
            "grid_size": [[-half_x, half_x], [-half_y, half_y]],
            "grid_step": [cell, cell],
            "features": REFERENCE_FEATURES[features],
            "align_to_vehicle_axes": True,
        },
    })
    return env_id, env


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the benchmark; returns steps/s per env and the ratios to highway-env."""
    import gymnasium as gym

    import dstenv  # noqa: F401  (registers the ids)

    quick = bool(getattr(args, "quick", False))
    repeats = int(getattr(args, "repeats", 0) or 0)
    steps = repeats if repeats > 0 else (40 if quick else 300)
    results: dict[str, Any] = {"steps": steps}

    ref_sps = 0.0
    for features in REFERENCE_FEATURES:
        env_id, ref = highway_reference((256, 256), 0.33, features)
        sps = time_env(ref, max(steps // 10, 10))
        ref.close()
        results[f"highway-env {env_id} OccupancyGrid 256x256 ({features})"] = sps
        ref_sps = ref_sps or sps  # the first (presence, vx, vy) is the reference

    cases = [
        ("DSTGrid-v0 256x256", "DSTGrid-v0"),
        ("DSTGrid-RL-v0 84x84", "DSTGrid-RL-v0"),
        ("DSTGrid-Highway-v0 84x84", "DSTGrid-Highway-v0"),
    ]
    for label, gid in cases:
        env = gym.make(gid)
        results[label] = time_env(env, steps)
        env.close()

    n_resets = 5 if quick else 20
    for label, pool in (("DSTGrid-RL-v0 reset ms, fresh map", 0),
                        ("DSTGrid-RL-v0 reset ms, map pool 10", 10)):
        env = gym.make("DSTGrid-RL-v0", config={"world": {"map": {"pool": pool}}})
        results[label] = time_resets(env, n_resets, pool)
        env.close()

    print(f"{'environment':76s} {'steps/s':>9s} {'x highway-env':>14s}")
    for key, sps in results.items():
        if key == "steps" or "reset ms" in key:
            continue
        print(f"{key:76s} {sps:9.1f} {sps / ref_sps:14.1f}")
    for key in [k for k in results if "reset ms" in k]:
        print(f"{key:76s} {results[key]:9.1f} ms")
    results["ratio_256_vs_highway"] = results["DSTGrid-v0 256x256"] / ref_sps
    results["ratio_rl_vs_highway"] = results["DSTGrid-RL-v0 84x84"] / ref_sps
    results["goal_met"] = bool(results["DSTGrid-v0 256x256"] >= 300
                               and results["ratio_256_vs_highway"] >= 10)
    return {k: (float(v) if isinstance(v, (np.floating, float)) else v) for k, v in results.items()}
