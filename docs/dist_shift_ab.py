"""Same-process A/B of the 3-D LIDAR's distance-bound blocks (``lidar3d.DIST_SHIFT``).

The ground walk of the 3-D LIDAR jumps by a lower bound of the distance to the
nearest raised cell, computed once per fresh map over blocks of ``2**shift`` cells
(:func:`dstenv.sensing.raised.raised_distance`). This generates the paper-protocol
3-D row of issue 16's goal table (stride 10, one worker, episodes of 200 steps with a
fresh map each, ``dstenv generate``'s serial path) with each shift in turn, in one
process, and prints the CPU ms per stored frame of every round and their medians::

    python docs/dist_shift_ab.py --shifts 0,1 --rounds 4 --frames 76

The returns do not depend on the shift (``tests/sensing/test_cast3d.py``), only the
time does: a coarser bound costs less per map and lets the walk jump a little less.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shifts", default="0,1", help="comma-separated shifts to alternate")
    ap.add_argument("--rounds", type=int, default=4, help="rounds of every shift")
    ap.add_argument("--frames", type=int, default=76, help="stored frames per run (19 a map)")
    args = ap.parse_args()
    shifts = [int(s) for s in args.shifts.split(",")]

    import dstenv.sensing.lidar3d as lidar3d
    from dstenv.data.bench_goals import _protocol, timed_generate
    from dstenv.pipeline import default_config

    cfg = _protocol(default_config(), True)
    if cfg is None:
        raise SystemExit("this build has no 3-D LIDAR or paper protocol")
    ms: dict[int, list[float]] = {s: [] for s in shifts}
    with tempfile.TemporaryDirectory(prefix="dstenv-ab-") as name:
        tmp = Path(name)
        timed_generate(cfg, 20, 1, tmp / "warm")  # compilation, caches, imports
        for k in range(args.rounds):
            for s in shifts:
                lidar3d.DIST_SHIFT = s
                _, cpu = timed_generate(cfg, args.frames, 1, tmp / f"{k}-{s}")
                ms[s].append(1e3 * cpu / args.frames)
                print(f"round {k}: shift {s}: {ms[s][-1]:.2f} ms CPU per frame", flush=True)
    for s in shifts:
        print(f"shift {s}: median {statistics.median(ms[s]):.2f} ms CPU per frame "
              f"({', '.join(f'{v:.2f}' for v in ms[s])})")


if __name__ == "__main__":
    main()
