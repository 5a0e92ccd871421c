"""Gridlock at junctions: the share of vehicle-steps standing still > 20 s outside a
planned halt, in the default city and the occlusion task's world (seeds 0-2, 60 s).

    python docs/gridlock.py
    python docs/gridlock.py 3-9    # other seeds (first-last)

Measured 2026-12-02 (docs/realism.md, "Junction gridlock"): default 3.14 % before the
junction fixes (requests looking through roundabout ring pieces and bends, circulating
traffic first), 0.60 % after them, 0.54 % once uncontrolled nodes whose paths conflict
became yield junctions; occlusion world 2.73 -> 1.22 -> 1.09 %.
"""

import sys

if __name__ == "__main__" and {"-h", "--help"} & set(sys.argv[1:]):  # usage: the docstring
    print(__doc__)
    raise SystemExit(0)

import sys

from dstenv.envs.registration import OCCLUDED_WORLD
from dstenv.sim import World
from dstenv.sim.routing import gridlocked

if __name__ == "__main__":
    lo, hi = (int(v) for v in (sys.argv[1] if len(sys.argv) > 1 else "0-2").split("-"))
    for name, cfg in (("default", None), ("occluded", OCCLUDED_WORLD)):
        runs = [gridlocked(World(cfg, seed=s), 600) for s in range(lo, hi + 1)]
        share = sum(r[0] for r in runs) / sum(r[1] for r in runs)
        print(f"{name}: {100 * share:.2f} % of vehicle-steps standing > 20 s "
              f"(seeds {lo}-{hi}: {', '.join(f'{100 * a / b:.2f}' for a, b in runs)})")
