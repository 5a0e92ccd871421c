"""Reset times of ``DSTGrid-RL-v0`` with a fresh map and with a pool of 10 maps (issue 17),
and of ``DSTGrid-v0`` (the paper's 256 x 256 grid) with a fresh map (issue 16's goal row).

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
    res = {"command": f"python docs/reset_times.py --out {args.out}",
           "date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "ms": {}}
    for label, env_id, pool in (("fresh map", "DSTGrid-RL-v0", 0),
                                ("map pool 10", "DSTGrid-RL-v0", 10),
                                ("DSTGrid-v0 fresh map", "DSTGrid-v0", 0)):
        env = gym.make(env_id, config={"world": {"map": {"pool": pool}}})
        runs = sorted(time_resets(env, args.resets, pool) for _ in range(args.runs))
        env.close()
        res["ms"][label] = {"median": round(runs[len(runs) // 2], 1),
                            "runs": [round(r, 1) for r in runs]}
        print(label, res["ms"][label])
    atomic_write_text(args.out, json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
