"""How many of each learned driver's held-out collisions are also the rule driver's:
the episodes (seeds) in which both crash, from ``evaluate.py --csv`` files::

    cd benchmarks/results/rl && python ../../../docs/shared_collisions.py \\
        --reference eval-grid-tuned-corridor-r3.csv eval-dagger-tuned-anchor-{asym,lr3e4,vec}-*.csv

Prints one line per (file, policy): its collisions and how many of them the
reference (the first policy of ``--reference``) shares.
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path


def collisions(path: Path) -> dict[str, set[int]]:
    """``{policy: seeds whose episode ended in a collision}`` of one CSV file."""
    out: dict[str, set[int]] = defaultdict(set)
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            out[row["policy"]]  # every policy, with or without a collision
            if row["collision"] == "True":
                out[row["policy"]].add(int(row["seed"]))
    return dict(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", required=True, type=Path)
    ap.add_argument("files", nargs="+", type=Path)
    args = ap.parse_args()
    ref_name, ref = next(iter(collisions(args.reference).items()))
    print(f"reference {ref_name}: {len(ref)} collisions")
    for path in args.files:
        for name, seeds in collisions(path).items():
            print(f"{path.name} | {name}: {len(seeds)} collisions, {len(seeds & ref)} shared")


if __name__ == "__main__":
    main()
