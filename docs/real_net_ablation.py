"""Which of real_net's three changes carries KITTI transfer (docs/benchmark.md, "A network
for real drives").

Generates the same simulated drives (the ``cpu`` preset's ``dense`` scenario, 3-D
LIDAR, a quarter without a map; 1000 frames, map seeds from 1000) at 128 x 128 and at
256 x 256 cells of 0.33 m, trains ``unet-light`` (the ``cpu`` preset's training
settings, 5 epochs, from scratch) with each combination below, and scores every
network on converted KITTI drives with ``dstenv.segment.benchmark.run_benchmark``
(visible cells, from step ``--from-step`` on, as the main job's KITTI section):

    python docs/real_net_ablation.py --kitti-data RUN/kitti/data --work /tmp/abl \\
        --out docs/real-net-ablation.json

About 20 minutes on 2 cores; rerun to resume (generation and training resume).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

#: name -> (grid, inputs, labels, seeds)
VARIANTS: dict[str, tuple[int, str, str, tuple[int, ...]]] = {
    "sim task: 128 cells, fcn10, full labels": (128, "fcn10", "full", (0,)),
    "256 cells, fcn10, full labels": (256, "fcn10", "full", (0,)),
    "256 cells, fcn10, KITTI labels": (256, "fcn10", "kitti", (0,)),
    "128 cells, fcn10+sensor, KITTI labels": (128, "fcn10+sensor", "kitti", (0,)),
    "real_net: 256 cells, fcn10+sensor, KITTI labels": (256, "fcn10+sensor", "kitti",
                                                        (0, 1, 2)),
}


def main() -> None:
    from dstenv.data import ShardDataset
    from dstenv.segment.benchmark import generate_data, run_benchmark
    from dstenv.segment.presets import preset_config
    from dstenv.segment.train import train

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kitti-data", required=True, type=Path, help="dstenv kitti convert output")
    ap.add_argument("--work", required=True, type=Path, help="data and checkpoints")
    ap.add_argument("--out", required=True, type=Path, help="JSON results")
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--epochs", type=int, default=5)
    ap.add_argument("--from-step", type=int, default=20)
    args = ap.parse_args()

    cpu = preset_config("cpu")
    timings: dict[str, float] = {}
    for grid in sorted({v[0] for v in VARIANTS.values()}):
        t = time.perf_counter()
        generate_data({**cpu["data"], "frames": args.frames, "grid": grid, "seed": 1000}, "sim",
                  args.work / f"data{grid}", progress=False)
        timings[f"data{grid}_s"] = time.perf_counter() - t
    ckpts = []
    for name, (grid, inputs, labels, seeds) in VARIANTS.items():
        data = {s: ShardDataset(args.work / f"data{grid}", split=s, inputs=inputs, labels=labels)
                for s in ("train", "val")}
        for seed in seeds:
            label = f"{name} (seed {seed})"
            mdir = args.work / "models" / f"{grid}-{inputs}-{labels}-seed{seed}"
            t = time.perf_counter()
            train({**cpu["train"], "model": "unet-light", "epochs": args.epochs, "seed": seed,
                   "device": "cpu", "inputs": inputs, "labels": labels},
                  data["train"], data["val"], mdir, progress=False, log=lambda m: None)
            timings[label] = time.perf_counter() - t
            print(f"{label}: trained in {timings[label]:.0f} s", flush=True)
            ckpts.append((label, str(mdir / "best.pt")))
    cfg = {"models": [], "device": "cpu", "examples": 1, "score_from_step": args.from_step,
           "tune": {"enabled": False}, "complete": {"enabled": False}}
    res = run_benchmark(cfg, args.work / "kitti-scores", data_dir=args.kitti_data,
                        progress=False, log=lambda m: None, checkpoints=ckpts)
    rows = {k: {c: round(v["visible"]["iou"][c], 3) for c in ("static", "moving")}
            for k, v in res["segmenters"].items()}
    out = {"command": "python docs/real_net_ablation.py --kitti-data "
                      f"{args.kitti_data} --work {args.work} --out {args.out}",
           "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "frames": args.frames, "epochs": args.epochs, "scored_from_step": args.from_step,
           "kitti_visible_iou": rows, "timings_s": {k: round(v, 1) for k, v in timings.items()}}
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    for k, v in rows.items():
        print(f"{k:60s} static {v['static']:.3f} moving {v['moving']:.3f}")


if __name__ == "__main__":
    main()
