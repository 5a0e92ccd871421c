"""Why the goal row's median is ~1.4x its minimum: the spread of the 3-D LIDAR chain
beside that of pure in-cache arithmetic, in one process, alternately.

``dstenv bench world`` times ``hdl64 sweep + sensor grid (goal 10)`` by a wall-clock
median; its CPU minimum is ~30 % lower. This times, in turns, each call CPU and wall:

* ``sweep+grid``: the goal row (the bench's generator, advancing: new noise every call);
* ``fixed rng``: the same with a fresh ``default_rng(0)`` every call (the same noise
  draws each time: data-dependent work would show as a narrower spread);
* ``cold cache``: the goal row after writing 64 MB (its working set evicted);
* ``np.sin x10``: ten ``np.sin`` of the bench's 256 x 256 reference (pure arithmetic
  on 0.5 MB: a spread here is the machine's, not the pipeline's).

It also reports the minor page faults per call of the goal row (``getrusage``).
``docs/realism-lidar.md`` (speed section, fifth round) quotes it::

    cd /tmp && PYTHONPATH=/path/to/dstenv python /path/to/dstenv/docs/lidar_spread.py 150
"""

import sys

if __name__ == "__main__" and {"-h", "--help"} & set(sys.argv[1:]):  # usage: the docstring
    print(__doc__)
    raise SystemExit(0)

import resource
import sys
import time

import numpy as np

from dstenv.grid import GridSpec
from dstenv.sensing.lidar3d import Hdl64
from dstenv.sim.bench import BENCH_CONFIG
from dstenv.sim.world import World

rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 100
world = World(BENCH_CONFIG, seed=0)  # the world of `dstenv bench world`
for _ in range(20):
    world.step()
spec = GridSpec()
rng = np.random.default_rng(0)
hdl = Hdl64({"model": "hdl64"})
x = np.random.default_rng(0).random((256, 256))
junk = np.ones(1 << 23)  # 64 MB


def goal(generator=None):
    return hdl.sweep(world.map, world.agents, world.ego_pose, generator or rng,
                     world.ego_speed).sensor_grid(spec)


cases = {"sweep+grid": goal, "fixed rng": lambda: goal(np.random.default_rng(0)),
         "cold cache": goal, "np.sin x10": lambda: [np.sin(x) for _ in range(10)]}
for f in cases.values():
    f()
cpu: dict[str, list[float]] = {k: [] for k in cases}
wall: dict[str, list[float]] = {k: [] for k in cases}
r0 = resource.getrusage(resource.RUSAGE_SELF)
for _ in range(rounds):
    for name, f in cases.items():
        if name == "cold cache":
            junk += 1.0  # untimed: evicts the caches
        w0 = time.perf_counter()
        c0 = time.process_time()
        f()
        cpu[name].append(time.process_time() - c0)
        wall[name].append(time.perf_counter() - w0)
r1 = resource.getrusage(resource.RUSAGE_SELF)
for name in cases:
    c, w = np.array(cpu[name]) * 1e3, np.array(wall[name]) * 1e3
    mc, mw = np.median(c), np.median(w)
    print(f"{name:11s} CPU min {c.min():6.2f} median {mc:6.2f} (x{mc / c.min():.2f})"
          f"  wall min {w.min():6.2f} median {mw:6.2f} (x{mw / w.min():.2f}) [ms]")
print(f"minor page faults per round (all four cases): {(r1.ru_minflt - r0.ru_minflt) / rounds:.1f};"
      f" {rounds} rounds")
