"""The write path per 256 x 256 frame (labels + ShardWriter, one core), as ``dstenv bench
data --goals`` measures it (:func:`dstenv.data.bench_goals._write_path_ms`), repeated
in one process so that two checkouts can be compared run for run::

    PYTHONPATH=/path/to/checkout python docs/write_path.py --runs 5 --out F.json

(run from a directory that is not a checkout, so that ``PYTHONPATH`` picks the code;
alternate the checkouts). Prints and writes the median and every run's split.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--frames", type=int, default=32, help="stride-10 frames per run")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    import dstenv
    from dstenv.data import bench_goals
    from dstenv.data.sampling import scenario_config

    root = Path(dstenv.__file__).resolve().parents[1]
    commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    config = scenario_config(None, {"grid": {"height": 256, "width": 256}})
    with tempfile.TemporaryDirectory() as d:
        runs = [bench_goals._write_path_ms(config, args.frames, Path(d)) for _ in range(args.runs)]
    result = {"command": " ".join(["python", "docs/write_path.py", *(argv or sys.argv[1:])]),
              "checkout": str(root), "commit": commit,
              "utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
              "median_cpu_ms": statistics.median(r["cpu_ms"] for r in runs),
              "median_labels_cpu_ms": statistics.median(r["labels_cpu_ms"] for r in runs),
              "median_writer_cpu_ms": statistics.median(r["writer_cpu_ms"] for r in runs),
              "runs": runs}
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"{commit}: write path {result['median_cpu_ms']:.3f} ms CPU (labels "
          f"{result['median_labels_cpu_ms']:.3f} + writer {result['median_writer_cpu_ms']:.3f}), "
          f"{runs[0]['bytes_per_frame']:.0f} B/frame")
    return result


if __name__ == "__main__":
    main()
