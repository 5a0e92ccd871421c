"""Old and new 3-D LIDAR sweep + road in one process: minimum CPU time, alternately.

On a loaded machine wall-clock medians and separate processes hide differences of a
few per cent; this times a copy of an older ``dstenv`` (renamed ``dstenv_old``)
against the current one in turns, in one process (``docs/realism-lidar.md``; its
second round used OLD = aa76a0a, its third 997b2d4, its fourth 90fcc83). First it
checks that both give the same results: the bench world's sweep (cloud, channels,
columns, surfaces, indices) and sensor grid, with and without yaw rate, and the
road (grid, plane, masks, heights) on every KITTI scan of ``/work/shared/data`` if
present; it stops at the first difference::

    mkdir -p /tmp/old && git archive OLD dstenv | tar -x -C /tmp/old   # OLD: a commit
    cd /tmp/old && mv dstenv dstenv_old
    grep -rl dstenv dstenv_old --include=*.py | xargs sed -i 's/\\bdstenv\\b/dstenv_old/g'
    cd /tmp && PYTHONPATH=/path/to/dstenv python /path/to/dstenv/docs/lidar_speed_ab.py \\
        /tmp/old 60
"""

import glob
import sys
import time

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


def same(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


for yaw_rate in (0.0, 0.3):
    a, b = (lidar.sweep(world.map, world.agents, world.ego_pose, np.random.default_rng(5),
                        world.ego_speed, yaw_rate) for lidar in lidars.values())
    fields = ("points", "channel", "column", "surface", "index")
    assert same([getattr(a, f) for f in fields], [getattr(b, f) for f in fields]), yaw_rate
    assert np.array_equal(a.sensor_grid(spec), b.sensor_grid(spec)), yaw_rate
scans = sorted(glob.glob("/work/shared/data/kitti-tracking/training/velodyne/*/*.bin"))
for path in scans:
    scan = np.fromfile(path, np.float32).reshape(-1, 4)
    assert same(cloud_sensor_grid(scan, spec), old_road(scan, spec)), path
print(f"same results: bench-world sweeps and grids, {len(scans)} KITTI scans")
cases = {}
for name, lidar in lidars.items():
    cloud = sweep(lidar)
    cases[f"{name} sweep"] = lambda lidar=lidar: sweep(lidar)
    cases[f"{name} road"] = lambda cloud=cloud: cloud.sensor_grid(spec)
    cases[f"{name} total"] = lambda lidar=lidar: sweep(lidar).sensor_grid(spec)
for f in cases.values():
    f()
best = dict.fromkeys(cases, np.inf)
for _ in range(int(sys.argv[2]) if len(sys.argv) > 2 else 50):
    for key, f in cases.items():
        t0 = time.process_time()
        f()
        best[key] = min(best[key], time.process_time() - t0)
print("  ".join(f"{k}={v * 1e3:.2f}" for k, v in best.items()), "[ms CPU, min]")
print("old/new:", "  ".join(f"{s} {best['old ' + s] / best['new ' + s]:.2f}"
                            for s in ("sweep", "road", "total")))
