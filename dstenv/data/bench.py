"""``dstenv bench data``: labelled frames per second / hour and bytes per frame on disk.

Measured in one process against references taken in the same run, so the ratios
hold on any machine:

* **pipeline step alone** (world + LIDAR + grids + DST + labels, no storage): the
  ceiling of single-process generation at stride 1; and the step without a
  :class:`~dstenv.frame.Frame` (``Pipeline.advance``) that generation uses between
  kept frames;
* **generate**: ``dstenv generate`` end to end (simulation, quantisation,
  compression, checksums, atomic shard files, manifest) with every step kept
  (stride 1) and at the default stride 10 (one frame per simulated second), with 1
  and 2 worker processes, with a new city per episode and with 4 episodes per city
  (``--episodes-per-map 4``); figures include Pipeline construction, city
  generation, and for the pool process start-up (~1-2 s);
* the goal rows of the issue first (:mod:`dstenv.data.bench_goals`; ``--goals``
  stops after them);
* the previous default (zlib level 3) at stride 1, 1 worker, as the in-process
  reference of the storage path;
* **bytes per frame**: real frames (stride 10) stored with each encoding, against
  the uncompressed float32 reference (10 probability channels as float32 plus the
  uint8 grids).

Each generate figure is the median of ``--repeats`` runs (default 3; 1 with ``--quick``).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from itertools import islice
from pathlib import Path
from typing import Any

from dstenv.data.bench_goals import timed_generate
from dstenv.data.sampling import episode_seeds, iter_frames, scenario_config
from dstenv.data.shards import ShardWriter

__all__ = ["run"]

#: name -> ShardWriter keyword arguments
ENCODINGS: dict[str, dict[str, Any]] = {
    "uint8+isal1 (default)": {"quantize": True, "compression": "gzip", "compression_opts": 1},
    "uint8+isal2": {"quantize": True, "compression": "gzip", "compression_opts": 2},
    "uint8+zlib3 (previous)": {"quantize": True, "compression": "gzip", "compression_opts": 3,
                               "deflate": "zlib"},
    "uint8+zlib1": {"quantize": True, "compression": "gzip", "compression_opts": 1,
                    "deflate": "zlib"},
    "uint8+zlib6": {"quantize": True, "compression": "gzip", "compression_opts": 6,
                    "deflate": "zlib"},
    "uint8+lzf": {"quantize": True, "compression": "lzf", "compression_opts": None},
    "float32+isal1": {"quantize": False, "compression": "gzip", "compression_opts": 1},
    "uint8 uncompressed": {"quantize": True, "compression": None, "compression_opts": None},
}


def _pipeline_rate(config: dict[str, Any], steps: int, frame: bool = True) -> float:
    from dstenv.pipeline import Pipeline

    p = Pipeline(config)
    p.reset(12345)
    p.step()  # numba compilation and caches out of the timing
    step = p.step if frame else p.advance
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    return steps / (time.perf_counter() - t0)


def _encodings(config: dict[str, Any], n: int, tmp: Path) -> dict[str, Any]:
    from dstenv.pipeline import Pipeline

    frames = list(islice(iter_frames(lambda: Pipeline(config), episode_seeds(7, "train", (0,)),
                                     200, 10, 10), n))
    h, w = frames[0].shape
    raw = (10 * 4 + 4) * h * w  # float32 BetP at t, t-1 + labels, visible, sensor, gis
    out: dict[str, Any] = {"reference_float32_bytes_per_frame": raw, "frames": n}
    attrs = {"config": config, "seed": 7}
    for name, kw in ENCODINGS.items():
        path = tmp / f"enc-{len(out)}.h5"
        t0 = time.perf_counter()
        with ShardWriter(path, attrs, **kw) as wr:
            for f in frames:
                wr.add(f)
        dt = time.perf_counter() - t0
        size = path.stat().st_size / n
        out[name] = {"bytes_per_frame": size, "write_ms_per_frame": 1e3 * dt / n,
                     "ratio_to_float32": size / raw}
    return out


def _generate_rate(config: dict[str, Any], frames: int, workers: int, stride: int,
                   tmp: Path, repeat: int, **spec_kw: Any) -> dict[str, float]:
    rates, cpu_rates = [], []
    for r in range(repeat):
        out = tmp / f"gen-w{workers}-s{stride}-{len(list(tmp.iterdir()))}"
        wall, cpu = timed_generate(config, frames, workers, out, stride=stride, **spec_kw)
        rates.append(frames / wall)
        cpu_rates.append(frames / max(cpu, 1e-9))
        size = sum(p.stat().st_size for p in out.rglob("*.h5"))
    rate = statistics.median(rates)
    return {"frames_per_s": rate, "frames_per_hour": 3600 * rate, "bytes_per_frame": size / frames,
            "frames": frames, "runs_frames_per_s": rates,
            "frames_per_cpu_hour": 3600 * statistics.median(cpu_rates)}


#: generate variants: label -> (workers, stride, episodes per map, gzip level, engine)
VARIANTS: dict[str, tuple[int, int, int, int, str]] = {
    "w1 stride1 zlib3 (previous)": (1, 1, 1, 3, "zlib"),
    "w1 stride1": (1, 1, 1, 1, "isal"),
    "w2 stride1": (2, 1, 1, 1, "isal"),
    "w1 stride10": (1, 10, 1, 1, "isal"),
    "w2 stride10": (2, 10, 1, 1, "isal"),
    "w1 stride10 4ep/map": (1, 10, 4, 1, "isal"),
    "w2 stride10 4ep/map": (2, 10, 4, 1, "isal"),
}


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the benchmark at 256 x 256 and print a table; returns the figures."""
    quick = bool(getattr(args, "quick", False))
    size = int(getattr(args, "grid", 0) or 256)
    repeat = 1 if quick else int(getattr(args, "repeats", 0) or 3)
    config = scenario_config(None, {"grid": {"height": size, "width": size}})
    # frames per worker: stride 1 (4 episodes of 190 kept steps), stride 10 (8 episodes),
    # and frames stored for the encodings
    n1, n10, n_store = (20, 4, 6) if quick else (760, 152, 30)
    result: dict[str, Any] = {"grid": [size, size], "repeat": repeat}
    from dstenv.data.bench_goals import goal_rows, print_goals

    result["goals"] = goal_rows(config, repeat, quick)
    print_goals(result["goals"], repeat)
    if getattr(args, "goals", False):
        return result
    with tempfile.TemporaryDirectory(prefix="dstenv-bench-") as tmp_name:
        tmp = Path(tmp_name)
        step_rate = _pipeline_rate(config, n1 if quick else 200)
        result["pipeline_steps_per_s"] = step_rate
        result["pipeline_advance_per_s"] = _pipeline_rate(config, n1 if quick else 200, False)
        result["store"] = _encodings(config, n_store, tmp)
        gen: dict[str, Any] = {}
        for name, (workers, stride, eps, level, engine) in VARIANTS.items():
            frames = (n1 if stride == 1 else n10) * workers
            r = _generate_rate(config, frames, workers, stride, tmp, repeat,
                               episodes_per_map=eps, compression_level=level, deflate=engine)
            r["ratio_to_pipeline_step"] = r["frames_per_s"] / step_rate
            gen[name] = r
        result["generate"] = gen
    _print(result)
    return result


def _print(r: dict[str, Any]) -> None:
    h, w = r["grid"]
    print(f"grid {h}x{w}; pipeline step alone: {r['pipeline_steps_per_s']:.1f} steps/s "
          f"({3600 * r['pipeline_steps_per_s']:,.0f} per hour); without a Frame: "
          f"{r['pipeline_advance_per_s']:.1f} steps/s")
    print(f"generate (median of {r['repeat']})"
          f"{'frames/s':>12}{'frames/hour':>14}{'vs step':>9}{'B/frame':>10}"
          f"{'frames/CPU-hour':>17}")
    for name, g in r["generate"].items():
        print(f"{name:<30}{g['frames_per_s']:>10.1f}{g['frames_per_hour']:>14,.0f}"
              f"{g['ratio_to_pipeline_step']:>9.2f}{g['bytes_per_frame']:>10,.0f}"
              f"{g['frames_per_cpu_hour']:>17,.0f}")
    print("frames/CPU-hour x free cores = frames/hour of an idle machine (wall-clock rates "
          "here share the cores with whatever else runs)")
    store = r["store"]
    print(f"storage of {store['frames']} frames (stride 10); uncompressed float32 reference: "
          f"{store['reference_float32_bytes_per_frame']:,} B/frame")
    print(f"{'encoding':<24}{'B/frame':>10}{'vs float32':>12}{'write ms':>10}")
    for name, s in store.items():
        if isinstance(s, dict):
            print(f"{name:<24}{s['bytes_per_frame']:>10,.0f}{s['ratio_to_float32']:>12.3f}"
                  f"{s['write_ms_per_frame']:>10.2f}")
