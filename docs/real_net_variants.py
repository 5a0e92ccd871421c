"""``real_net`` variants (docs/benchmark.md, "A network for real drives"), each chosen and
judged as the main job would: trained with :func:`dstenv.segment.realnet.
train_real_networks` (the ``cpu`` preset's data, protocol, training and ``real_net``
settings; only the builder options differ), **selected** on KITTI 0003 frames 0-9 (the
fine-tuning frames, never scored: :func:`dstenv.segment.real.start_scores`) and
**scored** on frames 20-39 over visible cells with
:func:`dstenv.segment.benchmark.run_benchmark`, as the main job's KITTI section::

    python docs/real_net_variants.py --kitti /work/shared/data/kitti-tracking \\
        --work /tmp/rnv --out docs/real-net-variants.json

Every variant shares the same 600 generated frames (the ``cpu`` preset's map seeds,
so the ``none`` variant is the main job's ``kitti-labels`` networks). About 6 min a
variant on 2 cores; rerun to resume.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from pathlib import Path
from typing import Any

#: variant -> unet-light builder options (``model_kwargs``) and pipeline overrides of
#: the generated drives over the ``cpu`` preset's (``overrides``)
VARIANTS: dict[str, dict[str, Any]] = {
    "none": {},
    "betp_skip 1.0": {"model_kwargs": {"betp_skip": 1.0}},
    # the converted KITTI drives have no map: every simulated drive without one too
    "no map": {"overrides": {"gis": {"source": "none"}}},
}


def main() -> None:
    from dstenv.data import ShardDataset
    from dstenv.data.manifest import load_manifest
    from dstenv.segment.benchmark import _deep_update, run_benchmark
    from dstenv.segment.presets import preset_config
    from dstenv.segment.real import _convert, start_scores
    from dstenv.segment.realnet import train_real_networks
    from dstenv.segment.shardindex import split_index

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kitti", required=True, help="KITTI tracking root (training/...)")
    ap.add_argument("--sequences", default="0003")
    ap.add_argument("--work", required=True, type=Path, help="data and checkpoints")
    ap.add_argument("--out", required=True, type=Path, help="JSON results")
    ap.add_argument("--variants", default=",".join(VARIANTS),
                    help=f"comma-separated subset of: {', '.join(VARIANTS)}")
    ap.add_argument("--val-frames", type=int, default=10)
    ap.add_argument("--from-step", type=int, default=20)
    args = ap.parse_args()
    names = [v for v in args.variants.split(",") if v]
    unknown = [v for v in names if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"--variants: unknown {unknown}; choose from {list(VARIANTS)}")

    kdata = args.work / "kitti"
    _convert(args.kitti, args.sequences.split(","), None, kdata)
    manifest = load_manifest(kdata)
    ds = ShardDataset(kdata, split="test", inputs="fcn10")
    index, _ = split_index(ds.files)
    val = [k for k, fr in enumerate(index) if fr["step"] < args.val_frames]
    cpu = preset_config("cpu")
    rows: dict[str, Any] = {}
    timings: dict[str, float] = {}
    for name in names:
        var = VARIANTS[name]
        data = {**cpu["data"], "overrides": _deep_update(cpu["data"]["overrides"],
                                                         var.get("overrides", {}))}
        cfg = {**cpu, "data": data,
               "model_kwargs": {cpu["real_net"]["model"]: var.get("model_kwargs", {})}}
        t = time.perf_counter()
        # one data folder for all: the same frames, generated once (copied; resumes)
        ckpts, _ = _train(cfg, manifest, args.work, name, var.get("overrides", {}),
                          train_real_networks)
        timings[name] = time.perf_counter() - t
        vals = start_scores(ckpts, ds, val)
        cfg_s = {"models": [], "device": "cpu", "examples": 1,
                 "score_from_step": args.from_step,
                 "tune": {"enabled": False}, "complete": {"enabled": False}}
        res = run_benchmark(cfg_s, args.work / "scores" / name.replace(" ", "_"),
                            data_dir=kdata, progress=False, log=lambda m: None,
                            checkpoints=list(ckpts.items()))
        for label, row in res["segmenters"].items():
            key = label if row["kind"] != "learned" else f"{name}: {label}"
            iou = row["visible"]["iou"]
            rows[key] = {"val_miou": round(vals[label], 3) if label in vals else None,
                         "static": round(iou["static"], 3), "moving": round(iou["moving"], 3),
                         "miou": round(row["visible"]["miou"], 3)}
        print(f"{name}: {timings[name]:.0f} s", flush=True)
    out = {"command": "python docs/real_net_variants.py --kitti "
                      f"{args.kitti} --work {args.work} --out {args.out} "
                      f"--variants '{','.join(names)}'",
           "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "selection": f"mIoU over labelled cells of frames 0-{args.val_frames - 1}",
           "scored": f"visible cells, frames {args.from_step}-", "variants": VARIANTS,
           "rows": rows, "timings_s": {k: round(v, 1) for k, v in timings.items()}}
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    for k, v in rows.items():
        print(f"{k:55s} val {v['val_miou']} static {v['static']:.3f} moving "
              f"{v['moving']:.3f} mIoU {v['miou']:.3f}")


def _train(cfg, manifest, work, name, overrides, train_real_networks):
    """Train one variant's networks; variants with the same overrides share the frames
    (copied from the first one generated: generation resumes on a complete copy)."""
    import shutil

    out = work / "nets" / name.replace(" ", "_")
    key = hashlib.sha1(json.dumps(overrides, sort_keys=True).encode()).hexdigest()[:10]
    data = work / "data" / key
    if data.is_dir() and not (out / "data").exists():
        out.mkdir(parents=True, exist_ok=True)
        shutil.copytree(data, out / "data")
    ckpts, facts = train_real_networks({"config": cfg}, tuple(manifest["grid_shape"]),
                                       float(manifest["cell_size"]), out, log=lambda m: None)
    if not data.is_dir():
        shutil.copytree(out / "data", data)
    return ckpts, facts

if __name__ == "__main__":
    main()
