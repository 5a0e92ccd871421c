"""Where a stored frame's time goes in each generation row of issue 16's goal table.

One worker (``dstenv generate``'s serial path, in this process) makes ``--frames``
frames of each row's setting (stride 10, episodes of 200 steps with a fresh map each:
the settings of ``dstenv bench data``), after a warm-up run of 20 frames (numba caches,
imports). The pipeline's stages are wrapped with timers (thread CPU time): the reset
with a fresh map (city, first sweep and update included), the world steps, the LIDAR
sweep, the sensor grid, the GIS grid, the DST update (``GridTracker.step``), the label
grid and the shard writer; "other" is what is left of the run's CPU time (the frame
and sample bookkeeping, the HDF5 file's open and commit, the wrappers themselves)::

    python docs/frame_costs.py --frames 200 --out benchmarks/results/bench/frame-costs.json
    python docs/frame_costs.py --frames 400 --episodes-per-map 10   # maps reused

Printed and written per row: CPU ms per stored frame of each stage and the total, and
the frames per hour of two such workers on two idle cores (3600 s * 2 / total).
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

from dstenv.io import output_file

STAGES = ("reset (fresh map)", "world steps", "LIDAR sweep", "sensor grid", "GIS grid",
          "DST update", "label grid", "shard writer", "other")


class Timers:
    """CPU seconds per stage; a stage inside a reset counts as the reset."""

    def __init__(self) -> None:
        self.sec: dict[str, float] = defaultdict(float)
        self.in_reset = False

    def wrap(self, owner: Any, name: str, stage: str) -> Callable[[], None]:
        """Time ``owner.name`` as ``stage``; returns the undo."""
        fn = getattr(owner, name)

        def timed(*a: Any, **k: Any) -> Any:
            if self.in_reset:
                return fn(*a, **k)
            reset = stage == STAGES[0]
            self.in_reset = reset
            t0 = time.thread_time()
            try:
                return fn(*a, **k)
            finally:
                self.sec[stage] += time.thread_time() - t0
                if reset:
                    self.in_reset = False

        setattr(owner, name, timed)
        return lambda: setattr(owner, name, fn)


def row_costs(config: dict[str, Any], frames: int, tmp: Path,
              episodes_per_map: int = 1) -> dict[str, float]:
    """CPU ms per stored frame of each stage (:data:`STAGES`) and ``"total"``."""
    import dstenv.pipeline as pl
    from dstenv.data.bench_goals import timed_generate
    from dstenv.data.shards import ShardWriter
    from dstenv.dst.tracker import GridTracker
    from dstenv.sim.world import World

    timed_generate(config, 20, 1, tmp / "warm")  # compilation, caches, imports
    probe = pl.Pipeline(config)
    probe.reset(0)
    timers = Timers()
    undo = [timers.wrap(pl.Pipeline, "reset", STAGES[0]),
            timers.wrap(World, "step", STAGES[1]),
            timers.wrap(type(probe.lidar), "sweep", STAGES[2]),
            timers.wrap(type(probe.sweep), "sensor_grid", STAGES[3]),
            timers.wrap(pl, "gis_grid", STAGES[4]),
            timers.wrap(GridTracker, "step", STAGES[5]),
            timers.wrap(pl, "label_grid", STAGES[6]),
            timers.wrap(ShardWriter, "add", STAGES[7])]
    try:
        _, cpu = timed_generate(config, frames, 1, tmp / "run",
                                episodes_per_map=episodes_per_map)
    finally:
        for u in reversed(undo):
            u()
    out = {s: 1e3 * timers.sec[s] / frames for s in STAGES[:-1]}
    out["other"] = 1e3 * cpu / frames - sum(out.values())
    out["total"] = 1e3 * cpu / frames
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200, help="stored frames per row")
    ap.add_argument("--out", type=Path, help="also write the figures as JSON")
    ap.add_argument("--episodes-per-map", type=int, default=1, metavar="E",
                    help="episodes driven on each map (generate's option; default 1: a "
                         "fresh map each)")
    args = ap.parse_args()
    if args.frames < 20:
        ap.error("--frames: at least 20 (one episode holds 19)")
    if not 1 <= args.episodes_per_map <= 10_000:
        ap.error(f"--episodes-per-map must be in [1, 10000], got {args.episodes_per_map}")
    if args.out is not None:  # before minutes of timing, not after
        try:
            output_file(args.out, "--out")
        except ValueError as exc:
            ap.error(str(exc))

    import dstenv
    from dstenv.io import atomic_write_text
    from dstenv.data.bench_goals import _protocol
    from dstenv.pipeline import default_config

    base = default_config()
    rows = {"stride 10, 10 Hz fusion, 2-D LIDAR": base,
            "stride 10, paper protocol, 2-D LIDAR": _protocol(base, False),
            "stride 10, paper protocol, 3-D LIDAR": _protocol(base, True)}
    res: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="dstenv-costs-") as name:
        for k, (label, cfg) in enumerate(rows.items()):
            if cfg is None:
                continue
            costs = row_costs(cfg, args.frames, Path(name) / str(k), args.episodes_per_map)
            res[label] = {s: round(v, 3) for s, v in costs.items()}
            res[label]["frames_per_h_2_workers"] = round(2 * 3.6e6 / costs["total"])
            print(f"{label}: {costs['total']:.2f} ms CPU per frame, "
                  f"{res[label]['frames_per_h_2_workers']:,} frames/h on 2 idle cores")
            for s in STAGES:
                print(f"    {s:20s} {costs[s]:6.2f} ms")
    if args.out:
        atomic_write_text(args.out, json.dumps({
            "command": f"python docs/frame_costs.py --frames {args.frames}"
                       + (f" --episodes-per-map {args.episodes_per_map}"
                          if args.episodes_per_map != 1 else ""),
            "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "machine": f"{platform.processor() or platform.machine()}, "
                       f"dstenv {dstenv.__version__}",
            "unit": "CPU ms per stored frame, one worker", "rows": res}, indent=1) + "\n")


if __name__ == "__main__":
    main()
