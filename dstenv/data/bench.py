"""``dstenv bench data``: labelled frames per second / hour and bytes per frame on disk.

Measured in one process against references taken in the same run, so the ratios
hold on any machine:

* **pipeline step alone** (world + LIDAR + grids + DST + labels, no storage): the
  ceiling of single-process generation at stride 1;
* **generate**: ``dstenv generate`` end to end (simulation, quantisation,
  compression, checksums, atomic shard files, manifest) at stride 1 and at the
  default stride 10 (one frame per simulated second), with 1 and 2 worker processes
  (figures include Pipeline construction, episode resets with map generation, and
  for the pool, process start-up: a full run of 190 frames per worker at stride 1 is
  one episode each);
* **bytes per frame**: real frames (stride 10) stored with each encoding, against
  the uncompressed float32 reference (10 probability channels as float32 plus the
  uint8 grids).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from itertools import islice
from pathlib import Path
from typing import Any

from dstenv.data.generate import GenerateSpec, generate
from dstenv.data.sampling import episode_seeds, iter_frames, scenario_config
from dstenv.data.shards import ShardWriter

__all__ = ["run"]

#: name -> ShardWriter keyword arguments
ENCODINGS: dict[str, dict[str, Any]] = {
    "uint8+gzip6 (default)": {"quantize": True, "compression": "gzip", "compression_opts": 6},
    "uint8+gzip1": {"quantize": True, "compression": "gzip", "compression_opts": 1},
    "uint8+gzip4": {"quantize": True, "compression": "gzip", "compression_opts": 4},
    "uint8+gzip9": {"quantize": True, "compression": "gzip", "compression_opts": 9},
    "uint8+lzf": {"quantize": True, "compression": "lzf", "compression_opts": None},
    "float32+gzip6": {"quantize": False, "compression": "gzip", "compression_opts": 6},
    "uint8 uncompressed": {"quantize": True, "compression": None, "compression_opts": None},
}


def _pipeline_rate(config: dict[str, Any], steps: int) -> float:
    from dstenv.pipeline import Pipeline

    p = Pipeline(config)
    p.reset(12345)
    p.step()  # numba compilation and caches out of the timing
    t0 = time.perf_counter()
    for _ in range(steps):
        p.step()
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
                   tmp: Path) -> dict[str, float]:
    spec = GenerateSpec(config=config, frames=frames, seed=1, split="train",
                        frames_per_shard=max(1, frames // (2 * workers)), episode_length=200,
                        stride=stride, warmup=stride)
    out = tmp / f"gen-w{workers}-s{stride}"
    t0 = time.perf_counter()
    generate(spec, out, workers=workers, progress=False)
    rate = frames / (time.perf_counter() - t0)
    size = sum(p.stat().st_size for p in out.rglob("*.h5"))
    return {"frames_per_s": rate, "frames_per_hour": 3600 * rate, "bytes_per_frame": size / frames}


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the benchmark at 256 x 256 and print a table; returns the figures."""
    quick = bool(getattr(args, "quick", False))
    size = int(getattr(args, "grid", 0) or 256)
    config = scenario_config(None, {"grid": {"height": size, "width": size}})
    # frames per measurement: stride 1 (per worker), stride 10, stored for the encodings
    n1, n10, n_store = (20, 4, 6) if quick else (190, 38, 30)
    result: dict[str, Any] = {"grid": [size, size]}
    with tempfile.TemporaryDirectory(prefix="dstenv-bench-") as tmp_name:
        tmp = Path(tmp_name)
        step_rate = _pipeline_rate(config, n1)
        result["pipeline_steps_per_s"] = step_rate
        result["store"] = _encodings(config, n_store, tmp)
        gen: dict[str, Any] = {}
        for workers, stride in ((1, 1), (2, 1), (1, 10)):
            frames = n1 if stride == 1 else n10
            r = _generate_rate(config, frames * workers, workers, stride, tmp)
            r["ratio_to_pipeline_step"] = r["frames_per_s"] / step_rate
            gen[f"workers={workers} stride={stride}"] = r
        result["generate"] = gen
    _print(result)
    return result


def _print(r: dict[str, Any]) -> None:
    h, w = r["grid"]
    print(f"grid {h}x{w}; pipeline step alone: {r['pipeline_steps_per_s']:.1f} steps/s "
          f"({3600 * r['pipeline_steps_per_s']:,.0f} per hour)")
    print(f"{'generate':<24}{'frames/s':>10}{'frames/hour':>14}{'vs step':>9}{'B/frame':>10}")
    for name, g in r["generate"].items():
        print(f"{name:<24}{g['frames_per_s']:>10.1f}{g['frames_per_hour']:>14,.0f}"
              f"{g['ratio_to_pipeline_step']:>9.2f}{g['bytes_per_frame']:>10,.0f}")
    store = r["store"]
    print(f"storage of {store['frames']} frames (stride 10); uncompressed float32 reference: "
          f"{store['reference_float32_bytes_per_frame']:,} B/frame")
    print(f"{'encoding':<24}{'B/frame':>10}{'vs float32':>12}{'write ms':>10}")
    for name, s in store.items():
        if isinstance(s, dict):
            print(f"{name:<24}{s['bytes_per_frame']:>10,.0f}{s['ratio_to_float32']:>12.3f}"
                  f"{s['write_ms_per_frame']:>10.2f}")
