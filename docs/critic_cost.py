"""PPO's steps per second with and without the privileged critics (``ppo_grid.py --critic
privileged`` and ``privileged-vectors``), in one process, alternating, PPO alone (no warm
start), the anchored recipe's env config and extractor::

    python docs/critic_cost.py --steps 4096 --rounds 2 --out benchmarks/results/rl/critic-cost.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "baselines"))


def main() -> None:
    import ppo_grid

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=4096)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    cfg = json.dumps({"reward": {"collision": -100, "off_road": -10}, "action": {"repeat": 3}})
    critics = ("plain", "privileged", "privileged-vectors")
    rates: dict[str, list[float]] = {c: [] for c in critics}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for critic in critics:
                argv = ["--env-config", cfg, "--max-episode-steps", "200", "--extractor",
                        "route-cnn", "--total-timesteps", str(args.steps), "--map-pool", "10",
                        "--learning-rate", "3e-05", "--gamma", "0.98", "--checkpoint-every",
                        "0", "--verbose", "0", "--out", f"{tmp}/{critic}{r}"]
                if critic != "plain":
                    argv += ["--critic", critic]
                meta = ppo_grid.main(argv)
                rates[critic].append(round(meta["timesteps"] / meta["wall_time_s"], 1))
    plain = statistics.median(rates["plain"])
    record = {"command": "python " + " ".join(sys.argv),
              "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
              "steps_per_s": rates,
              **{f"ratio_{c.replace('-', '_')}_to_plain":
                 round(statistics.median(rates[c]) / plain, 3) for c in critics[1:]}}
    args.out.write_text(json.dumps(record, indent=2) + "\n")
    print(record)


if __name__ == "__main__":
    main()
