"""Frames per hour of ``dstenv generate`` for the goal rows of issue 16, over long runs.

``dstenv bench data --goals`` times a short and a three times longer run and takes the
extra frames over the extra time; with 40 / 120 frames per worker the difference of two
noisy wall times is itself noisy (a run slower than its short twin gives no figure).
This script does the same with larger runs: ``--frames`` N and then 4 N frames, rate =
3 N over the extra time (each run starts its own worker pool, whose start-up cancels),
after a warm-up run (numba caches compiled), ``--repeat`` pairs per row; it prints the
median rate and every pair::

    python docs/generation_rates.py --frames 160 --repeat 3 --out rates.json
    python docs/generation_rates.py --frames 160 --frames-per-shard 20   # the old shards

``--frames-per-shard`` (default: generate's, 256) and ``--episodes-per-map`` pass through
to every run; before 2026-12-07 the runs wrote shards of ``frames // (2 workers)``.

Run it from two checkouts one after the other (``PYTHONPATH=TREE``) for an A/B of two
versions on the same machine at the same time. Rows: stride 10 with 10 Hz fusion, and
the paper's protocol (``protocol.update_every = 10``) with the 2-D and the 3-D LIDAR;
episodes of 200 steps, a fresh map each, 2 workers (the settings of ``bench data``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

from dstenv.io import output_file


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=160, help="frames of the short run (N)")
    ap.add_argument("--repeat", type=int, default=3, help="timed pairs (N, 4 N frames) a row")
    ap.add_argument("--workers", type=int, default=2, help="generation processes")
    ap.add_argument("--frames-per-shard", type=int, default=0, metavar="N",
                    help="shard size of every run (default 0: generate's own)")
    ap.add_argument("--episodes-per-map", type=int, default=1, metavar="E",
                    help="episodes driven on each map (default 1: a fresh map each)")
    ap.add_argument("--out", type=Path, help="also write the figures as JSON")
    args = ap.parse_args()
    for name, low in (("frames", 1), ("repeat", 1), ("workers", 1), ("frames_per_shard", 0),
                      ("episodes_per_map", 1)):
        if getattr(args, name) < low:
            ap.error(f"--{name.replace('_', '-')} must be >= {low}, got {getattr(args, name)}")
    if args.out is not None:  # before minutes of timing, not after
        try:
            output_file(args.out, "--out")
        except ValueError as exc:
            ap.error(str(exc))
    kw = {"episodes_per_map": args.episodes_per_map}
    if args.frames_per_shard:
        kw["frames_per_shard"] = args.frames_per_shard

    import dstenv
    from dstenv.io import atomic_write_text
    from dstenv.data.bench_goals import _protocol, timed_generate
    from dstenv.pipeline import default_config

    base = default_config()
    rows = {"stride 10, 10 Hz fusion, 2-D LIDAR": base,
            "stride 10, paper protocol, 2-D LIDAR": _protocol(base, False),
            "stride 10, paper protocol, 3-D LIDAR": _protocol(base, True)}
    out: dict = {"dstenv": str(Path(dstenv.__file__).parent), "frames": args.frames,
                 "workers": args.workers, "frames_per_shard": args.frames_per_shard or None,
                 "episodes_per_map": args.episodes_per_map, "rows": {}}
    with tempfile.TemporaryDirectory(prefix="dstenv-rates-") as name:
        tmp = Path(name)
        for k, (label, cfg) in enumerate(rows.items()):
            timed_generate(cfg, 4 * args.workers, args.workers, tmp / f"warm-{k}")
            runs = []
            n = args.frames
            for r in range(args.repeat):
                short, c_short = timed_generate(cfg, n, args.workers, tmp / f"{k}-{r}-s", **kw)
                long, c_long = timed_generate(cfg, 4 * n, args.workers, tmp / f"{k}-{r}-l", **kw)
                runs.append({"short_s": short, "long_s": long,
                             "frames_per_h": 3600 * 3 * n / (long - short),
                             "cpu_ms_per_frame": 1e3 * (c_long - c_short) / (3 * n)})
            med = statistics.median(x["frames_per_h"] for x in runs)
            out["rows"][label] = {"frames_per_h": med, "runs": runs}
            print(f"{label:<42} {med:>12,.0f} frames/h  (runs: "
                  + ", ".join(f"{x['frames_per_h']:,.0f}" for x in runs)
                  + f"; CPU {statistics.median(x['cpu_ms_per_frame'] for x in runs):.1f} ms/frame)",
                  flush=True)
    if args.out:
        atomic_write_text(args.out, json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
