"""Old and new 3-D LIDAR sweep + road in one process: CPU time, alternately.

On a loaded machine wall-clock medians and separate processes hide differences of a few
per cent; this times a copy of an older ``dstenv`` (renamed ``dstenv_old``) against the
current one in turns, in one process (``docs/realism-lidar.md``; its second round used
OLD = aa76a0a, its third 997b2d4, its fourth 90fcc83, its fifth 2255cb4, its sixth
b160de0). First it counts where the two differ (the fifth round's float32 road and sweep
may, by rounding; issue 13 allows 0.1 % of cells and points, planes within 1e-4): the
sensor grids, ground and obstacle masks and planes of the bench world's sweeps (4 seeds,
with and without yaw rate; each version's own sweep through its own road) and of every
KITTI scan of the shared data (``../shared/data``, or
``$DSTENV_SHARED_DATA``) if present. Then it times both, minimum and median CPU time::

    mkdir -p /tmp/old && git archive OLD dstenv | tar -x -C /tmp/old   # OLD: a commit
    cd /tmp/old && mv dstenv dstenv_old
    grep -rl dstenv dstenv_old --include=*.py | xargs sed -i 's/\\bdstenv\\b/dstenv_old/g'
    cd /tmp && PYTHONPATH=/path/to/dstenv python /path/to/dstenv/docs/lidar_speed_ab.py \\
        /tmp/old 60
"""

import sys

if __name__ == "__main__" and {"-h", "--help"} & set(sys.argv[1:]):  # usage: the docstring
    print(__doc__)
    raise SystemExit(0)

import glob
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, sys.argv[1])

from dstenv.grid import GridSpec  # noqa: E402
from dstenv.sensing.cloud import cloud_sensor_grid  # noqa: E402
from dstenv.sensing.lidar3d import Hdl64  # noqa: E402
from dstenv.sim.bench import BENCH_CONFIG  # noqa: E402
from dstenv.sim.world import World  # noqa: E402
from dstenv_old.sensing.cloud import cloud_sensor_grid as old_road  # noqa: E402
from dstenv_old.sensing.lidar3d import Hdl64 as Hdl64Old  # noqa: E402

world = World(BENCH_CONFIG, seed=0)  # the world of `dstenv bench world`
for _ in range(20):
    world.step()
spec = GridSpec()
rng = np.random.default_rng(0)
lidars = {"old": Hdl64Old({"model": "hdl64"}), "new": Hdl64({"model": "hdl64"})}


def sweep(lidar):
    return lidar.sweep(world.map, world.agents, world.ego_pose, rng, world.ego_speed)


def count_diffs(totals: dict, new, old) -> None:
    """Add the differences of two sensor grids ``(H, W)`` and of two roads' masks to
    ``totals`` (cells, points, differing ones; the largest plane difference)."""
    totals["cells"] += new[0].size
    totals["cells differ"] += int((new[0] != old[0]).sum())
    if len(new) > 1:
        totals["points"] += new[2].size
        totals["ground differ"] += int((new[2] != old[2]).sum())
        totals["obstacle differ"] += int((new[3] != old[3]).sum())
        totals["max |plane diff|"] = max(totals["max |plane diff|"],
                                         float(np.abs(new[1] - old[1]).max()))


def report(name: str, totals: dict) -> None:
    print(f"{name}: " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                  for k, v in totals.items())
          + f" ({100 * totals['cells differ'] / max(totals['cells'], 1):.4f} % of cells)")


# old and new side by side: the road on KITTI and the sweep may differ by float32
# rounding (issue 13's rule: at most 0.1 % of cells and points, planes within 1e-4)
sims = dict.fromkeys(("cells", "cells differ", "points", "ground differ", "obstacle differ"), 0)
sims["max |plane diff|"] = 0.0
for seed in range(4):
    for yaw_rate in (0.0, 0.3):
        b, a = (lidar.sweep(world.map, world.agents, world.ego_pose, np.random.default_rng(seed),
                            world.ego_speed, yaw_rate) for lidar in lidars.values())
        offset = tuple(float(v) for v in a.mount)
        count_diffs(sims, cloud_sensor_grid(a.points, spec, offset=offset),  # a: new, b: old
                    old_road(b.points, spec, offset=offset))
report("bench-world sweeps (4 seeds x 2 yaw rates)", sims)
kitti = dict(sims, **dict.fromkeys(sims, 0))
kitti["max |plane diff|"] = 0.0
shared = os.environ.get("DSTENV_SHARED_DATA",  # ../shared/data beside the checkout
                        str(Path(__file__).resolve().parents[2] / "shared" / "data"))
scans = sorted(glob.glob(f"{shared}/kitti-tracking/training/velodyne/*/*.bin"))
for path in scans:
    scan = np.fromfile(path, np.float32).reshape(-1, 4)
    count_diffs(kitti, cloud_sensor_grid(scan, spec), old_road(scan, spec))
report(f"{len(scans)} KITTI scans", kitti)
cases = {}
for name, lidar in lidars.items():
    cloud = sweep(lidar)
    cases[f"{name} sweep"] = lambda lidar=lidar: sweep(lidar)
    cases[f"{name} road"] = lambda cloud=cloud: cloud.sensor_grid(spec)
    cases[f"{name} total"] = lambda lidar=lidar: sweep(lidar).sensor_grid(spec)
for f in cases.values():
    f()
times: dict[str, list[float]] = {key: [] for key in cases}
for _ in range(int(sys.argv[2]) if len(sys.argv) > 2 else 50):
    for key, f in cases.items():
        t0 = time.process_time()
        f()
        times[key].append(time.process_time() - t0)
for stat in (np.min, np.median):
    best = {k: float(stat(v)) for k, v in times.items()}
    print("  ".join(f"{k}={v * 1e3:.2f}" for k, v in best.items()), f"[ms CPU, {stat.__name__}]")
    print("old/new:", "  ".join(f"{s} {best['old ' + s] / best['new ' + s]:.2f}"
                                for s in ("sweep", "road", "total")))
