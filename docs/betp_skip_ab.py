"""BetP skipped on fused steps without a frame: old vs new in one process.

1. the in-place 256 x 256 update writing BetP vs ``betp=None`` (median of 30
   alternating blocks of 10 updates, thread CPU);
2. a stored frame at stride 10 with 10 Hz fusion (ten pipeline steps, reset untimed):
   the pipeline module of a previous commit, loaded beside this one, vs this one.
   Both drive this checkout's tracker and filter; the old module never skips BetP.

    git show a276c24:dstenv/pipeline.py > /tmp/old_pipeline.py
    python docs/betp_skip_ab.py /tmp/old_pipeline.py

Figures in docs/throughput.md, section 4.
"""

import sys

if __name__ == "__main__" and {"-h", "--help"} & set(sys.argv[1:]):  # usage: the docstring
    print(__doc__)
    raise SystemExit(0)

import importlib.util
import statistics
import sys
import time

import numpy as np

from dstenv.data.sampling import scenario_config
from dstenv.dst import PerceptionGridFilter
from dstenv.dst._kernel import history_rows, inplace_update
from dstenv.dst.bench import street_inputs
from dstenv.pipeline import Pipeline


def kernel() -> None:
    sensor, gis = street_inputs(256)
    f = PerceptionGridFilter((256, 256))
    geo = np.array([np.cos(0.004), np.sin(0.004), 0.33, 0.02, 0.33])
    k_hist, desc = history_rows(geo, (256, 256))
    hist = np.empty((f._hist.shape[0], max(k_hist, 1) * 256), np.float32)

    def run(betp):
        inplace_update(f._buf[0], f._zbuf[0], sensor, gis, True, geo, f._prm, betp, hist,
                       k_hist, desc)

    run(f._betp)
    run(None)
    res = {"betp": [], "none": []}
    for r in range(30):
        for name in (("betp", "none") if r % 2 else ("none", "betp")):
            c = time.thread_time()
            for _ in range(10):
                run(f._betp if name == "betp" else None)
            res[name].append((time.thread_time() - c) / 10 * 1e3)
    m = {k: statistics.median(v) for k, v in res.items()}
    print("in-place update 256x256, CPU ms:", {k: round(v, 3) for k, v in m.items()},
          f"ratio {m['none'] / m['betp']:.3f}")


def pipeline(old_path: str, rounds: int = 21) -> None:
    spec = importlib.util.spec_from_file_location("old_pipeline", old_path)
    old = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(old)
    cfg = scenario_config(None, {})
    pipes = {"old": old.Pipeline(cfg), "new": Pipeline(cfg)}
    res = {k: [] for k in pipes}
    for r in range(rounds):
        for name, p in pipes.items():
            p.reset(3 + r % 2)
            for k in range(1, 11):  # warm-up, untimed
                p.advance() if k % 10 else p.step()
            c = time.thread_time()
            for k in range(11, 111):
                p.step() if k % 10 == 0 else p.advance()
            res[name].append((time.thread_time() - c) / 10 * 1e3)
    m = {k: statistics.median(v) for k, v in res.items()}
    paired = statistics.median(b / a for a, b in zip(res["old"], res["new"]))
    print("CPU ms per stored frame (stride 10, 10 Hz fusion):",
          {k: round(v, 2) for k, v in m.items()},
          f"ratio {m['new'] / m['old']:.3f}, paired median {paired:.3f}")


if __name__ == "__main__":
    kernel()
    pipeline(sys.argv[1])
