"""``dstenv bench NAME``: speed benchmarks (never timed unit tests).

Each benchmark lives beside the code it measures as a function
``run(args) -> dict`` in the module named in :data:`BENCHMARKS`, prints a table,
and reports ratios against a reference run made in the same process, so the
figures mean something on any machine.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from dstenv.config import CLIError

__all__ = ["BENCHMARKS", "median_ms", "register", "run_benchmark"]

#: benchmark name -> (module with ``run(args)``, one-line description)
BENCHMARKS: dict[str, tuple[str, str]] = {
    "fusion": ("dstenv.dst.bench", "PerceptionGridFilter.update at 64/128/256 vs plain numpy"),
    "sensing": (
        "dstenv.sensing.bench",
        "LIDAR sweep, sensor/GIS/label grids at 256x256 (1800 beams, 40 agents)",
    ),
    "world": ("dstenv.sim.bench", "world step + LIDAR sweep + grids + labels at 256x256"),
    "env": ("dstenv.envs.bench", "DSTGrid-v0 steps/s vs highway-env OccupancyGrid"),
    "data": ("dstenv.data.bench", "labelled frames per hour and bytes per frame on disk"),
}


def median_ms(fn: Callable[[], Any], repeats: int, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls [ms], after ``warmup`` calls.

    The warm-up calls compile numba kernels and fill caches; the median resists the
    noise of a shared machine better than the mean.
    """
    return median_min_ms(fn, repeats, warmup)[0]


def median_min_ms(fn: Callable[[], Any], repeats: int, warmup: int = 1) -> tuple[float, float]:
    """``(median, minimum)`` wall time of ``fn()`` over ``repeats`` calls [ms] (see
    :func:`median_ms`). The minimum is the cost of the code on an undisturbed core;
    the median adds what the machine's own spread adds (on the shared 2-core VM a
    plain ``np.sin`` loop has a median 1.45x its minimum: ``docs/lidar_spread.py``).
    """
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times) * 1e3), float(np.min(times) * 1e3)


def run_benchmark(name: str, args: argparse.Namespace) -> dict[str, Any]:
    """Run one benchmark by name and return its result dict."""
    if name not in BENCHMARKS:
        raise ValueError(f"unknown benchmark {name!r}; choose from {', '.join(BENCHMARKS)}")
    module = importlib.import_module(BENCHMARKS[name][0])
    return module.run(args)


def _cmd(args: argparse.Namespace) -> int:
    from dstenv.io import atomic_write_text, output_file

    names = list(BENCHMARKS) if args.name == "all" else [args.name]
    if args.repeats < 0:
        raise ValueError(f"--repeats must be >= 0 (0: automatic), got {args.repeats}")
    if args.goals and args.name not in ("data", "all"):
        raise ValueError(f"--goals goes with bench data (its goal rows), not bench {args.name}")
    if args.json is not None:  # "" too: a name, not "no file"
        output_file(args.json, "--json")  # before minutes of timing, not after
    results = {}
    try:
        for name in names:
            print(f"== bench {name}: {BENCHMARKS[name][1]}")
            results[name] = run_benchmark(name, args)
    except KeyboardInterrupt:  # keep the benchmarks that finished (bench all: minutes each)
        if args.json and results:
            atomic_write_text(args.json, json.dumps({**results, "interrupted": True}, indent=2,
                                                    default=float))
            print(f"dstenv bench: the finished benchmarks ({', '.join(results)}) are in "
                  f"{args.json}", file=sys.stderr)
        raise
    if args.json:
        text = json.dumps(results, indent=2, default=float)
        try:
            atomic_write_text(args.json, text)
        except OSError as exc:  # after minutes of timing: keep the results somewhere
            fd, kept = tempfile.mkstemp(prefix="dstenv-bench-", suffix=".json")
            with os.fdopen(fd, "w") as fh:
                fh.write(text)
            raise CLIError(f"--json {args.json}: cannot write it ({exc.strerror or exc}); the "
                           f"results are in {kept} instead") from None
        print(f"wrote {args.json}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``dstenv bench`` to the CLI."""
    from dstenv.cli import plain

    p = sub.add_parser("bench", help="run a speed benchmark", description=plain(
        "``dstenv bench NAME``: speed benchmarks. Each prints a table and reports ratios "
        "against a reference run made in the same process, so the figures mean something on "
        "any machine; ``bench data --goals`` gives the throughput goal rows (README)."))
    p.add_argument("name", choices=[*BENCHMARKS, "all"], help="which benchmark")
    p.add_argument("--repeats", type=int, default=0, help="timed repetitions (0: automatic)")
    p.add_argument("--quick", action="store_true", help="fewer repetitions, for a smoke run")
    p.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    p.add_argument("--goals", action="store_true",
                   help="bench data: only the goal rows (frames/h, reset, write path, env, DST)")
    p.set_defaults(func=_cmd)
