"""Distribution of issue 13's goal row (hdl64 sweep + ground removal + sensor grid).

Times ``Hdl64.sweep(...).sensor_grid(spec)`` on ``dstenv bench world``'s world
(``BENCH_CONFIG``, seed 0) after STEPS world steps, 200 calls after 5 of warm-up, and
prints the 5/25/50/75/95th percentiles of the wall time [ms] and the minor page
faults per call. The bench's own rows run in one process after ~620 world steps of
other rows; bursts of the shared VM's noise land on whichever row is running::

    python docs/lidar_chain_spread.py 20
    python docs/lidar_chain_spread.py 320
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

world = World(BENCH_CONFIG, seed=0)
for _ in range(int(sys.argv[1]) if len(sys.argv) > 1 else 20):
    world.step()
spec = GridSpec()
rng = np.random.default_rng(0)
hdl = Hdl64({"model": "hdl64"})


def chain() -> None:
    hdl.sweep(world.map, world.agents, world.ego_pose, rng, world.ego_speed).sensor_grid(spec)


for _ in range(5):
    chain()
ts, faults = [], []
for _ in range(200):
    r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    t = time.perf_counter()
    chain()
    ts.append((time.perf_counter() - t) * 1e3)
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0)
print("percentiles 5/25/50/75/95 [ms]:", np.percentile(ts, [5, 25, 50, 75, 95]).round(2))
print("minor page faults per call:", float(np.mean(faults)))
