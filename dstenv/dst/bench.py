"""``dstenv bench fusion``: PerceptionGridFilter.update against the plain-numpy reference."""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

import numpy as np

from dstenv.dst.filter import PerceptionGridFilter
from dstenv.dst.params import DSTParams
from dstenv.dst.reference import reference_update
from dstenv.dst.rules import vacuous

__all__ = ["run", "street_inputs"]


def street_inputs(size: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A street-like sensor grid and map of ``size x size`` cells for timing.

    A road band with intermediate verges and building blocks, a LIDAR view that is
    free near the ego, occupied on a few obstacles and unknown beyond ~60% of the
    half-width: roughly the mix of cases a real sweep produces.

    Returns:
        ``(sensor, gis)``, both ``(size, size) uint8``.
    """
    rng = np.random.default_rng(seed)
    gis = np.full((size, size), 3, np.uint8)
    c = size // 2
    gis[:, c - size // 10 : c + size // 10] = 2
    gis[:, : size // 4] = 1
    gis[:, -size // 4 :] = 1
    yy, xx = np.mgrid[:size, :size]
    r = np.hypot(yy - c, xx - c)
    sensor = np.where(r < 0.6 * c, 1, 0).astype(np.uint8)
    sensor[(gis == 1) & (r < 0.7 * c)] = 2
    for _ in range(max(1, size // 16)):
        i, j = rng.integers(0, size - 6, 2)
        sensor[i : i + 5, j : j + 3] = 2
    return sensor, gis


def _time(fn, repeats: int, rounds: int = 3) -> float:
    fn()  # warm-up (and numba compilation)
    best = np.inf
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(repeats):
            fn()
        best = min(best, (time.perf_counter() - t0) / repeats)
    return best


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Time one update at 64, 128 and 256 cells a side; print and return a table."""
    quick = bool(getattr(args, "quick", False))
    repeats = int(getattr(args, "repeats", 0) or 0)
    params = DSTParams.default()
    motion = (0.33, 0.02, 0.004)  # ~3.3 m/s at 10 Hz, slight curve
    threads = min(2, os.cpu_count() or 1)
    rows = {}
    print(f"{'grid':>9} {'fast [ms]':>10} {'updates/s':>10} {'copy=True':>10} "
          f"{f'{threads} thr [ms]':>11} {'reference [ms]':>15} {'speed-up':>9}")
    for size in (64, 128, 256):
        sensor, gis = street_inputs(size)
        f = PerceptionGridFilter((size, size), params)
        f_mt = PerceptionGridFilter((size, size), params, threads=threads)
        n = repeats or (20 if quick else max(20, 400 * 64 // size))
        fast = _time(lambda: f.update(sensor, gis, motion, copy=False), n, 3 if quick else 7)
        fast_copy = _time(lambda: f.update(sensor, gis, motion), repeats or (10 if quick else 100))
        fast_mt = _time(lambda: f_mt.update(sensor, gis, motion, copy=False), n)
        state = [vacuous((size, size)), np.zeros((size, size), np.float32)]

        def ref_step() -> None:
            state[0], state[1] = reference_update(
                state[0], state[1], sensor, gis, params, f.cell_size, motion
            )

        ref = _time(ref_step, 2 if quick else 5)
        rows[f"{size}x{size}"] = {
            "fast_ms": fast * 1e3,
            "fast_with_copy_ms": fast_copy * 1e3,
            "updates_per_s": 1.0 / fast,
            f"fast_{threads}_threads_ms": fast_mt * 1e3,
            "reference_ms": ref * 1e3,
            "speedup": ref / fast,
        }
        print(f"{size:>4}x{size:<4} {fast * 1e3:>10.3f} {1 / fast:>10.0f} {fast_copy * 1e3:>10.3f} "
              f"{fast_mt * 1e3:>11.3f} {ref * 1e3:>15.1f} {ref / fast:>8.0f}x")
    print("fast = update(copy=False) incl. ego-motion warp and BetP, one thread (the default);"
          f" copy=True adds a fresh (32, H, W) array; '{threads} thr' = threads={threads}, which"
          " only pays on idle cores; reference = dstenv.dst.reference.reference_update"
          " (dense numpy); speed-up = reference / fast")
    return rows
