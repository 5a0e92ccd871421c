"""Reset times of ``DSTGrid-RL-v0`` with a fresh map and with a pool of 10 maps (issue 17),
and of ``DSTGrid-v0`` (the paper's 256 x 256 grid) with a fresh map (issue 16's goal row),
also with the 3-D LIDAR (``lidar.model = "hdl64"``: its per-map tables are built at the
first sweep of a map, inside the reset).

The timer is :func:`dstenv.envs.bench.time_resets`, the one ``dstenv bench env`` uses;
three runs of 20 resets each, median reported::

    python docs/reset_times.py --out benchmarks/results/bench/reset-times.json
"""

from __future__ import annotations

import argparse
import json
from datetime import datetime, timezone

import gymnasium as gym

import dstenv.envs  # noqa: F401  (registers the ids)
from dstenv.envs.bench import time_resets
from dstenv.io import atomic_write_text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--resets", type=int, default=20)
    args = ap.parse_args()
    import dstenv

    res = {"command": f"python docs/reset_times.py --runs {args.runs} --resets {args.resets} "
                      f"--out {args.out}", "checkout": str(dstenv.__file__),
           "date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "ms": {}}
    for label, env_id, pool, extra in (
            ("fresh map", "DSTGrid-RL-v0", 0, {}),
            ("map pool 10", "DSTGrid-RL-v0", 10, {}),
            ("DSTGrid-v0 fresh map", "DSTGrid-v0", 0, {}),
            ("DSTGrid-v0 fresh map, 3-D LIDAR", "DSTGrid-v0", 0, {"lidar": {"model": "hdl64"}})):
        env = gym.make(env_id, config={"world": {"map": {"pool": pool}}, **extra})
        runs = sorted(time_resets(env, args.resets, pool) for _ in range(args.runs))
        env.close()
        res["ms"][label] = {"median": round(runs[len(runs) // 2], 1),
                            "runs": [round(r, 1) for r in runs]}
        print(label, res["ms"][label])
    atomic_write_text(args.out, json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
