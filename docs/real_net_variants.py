"""``real_net`` variants (docs/benchmark.md, "A network for real drives"), each chosen and
judged as the main job would: trained with :func:`dstenv.segment.realnet.
train_real_networks` (the ``cpu`` preset's data, protocol, training and ``real_net``
settings; only the builder options differ), **selected** on KITTI 0003 frames 0-9 (the
fine-tuning frames, never scored: :func:`dstenv.segment.real.start_scores`) and
**scored** on frames 20-39 over visible cells with
:func:`dstenv.segment.benchmark.run_benchmark`, as the main job's KITTI section::

    python docs/real_net_variants.py --kitti KITTI \\
        --work /tmp/rnv --out docs/real-net-variants.json

The variants draw the ``cpu`` preset's map seeds (600 frames unless a variant says
otherwise), so ``no map past kitti moving`` (seeds 0-2) is the main job's
``kitti-labels`` networks since 2026-12-06, ``no map`` the ones before and ``none`` the
ones before ``real_net.map``. About 4-6 min a 600-frame variant on 2 cores; rerun to
resume.
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
import time
from pathlib import Path
from typing import Any

#: variant -> overrides of the ``cpu`` preset (``real_net``, ``model_kwargs``) and of its
#: drives' pipeline (``data_overrides``, merged into ``data.overrides``); the drives are
#: treated as converted without a map (``real_map=False``), as 0003 is
#: (a variant that does not set ``real_net.moving`` or ``inputs`` has "run" and
#: "fcn10+sensor", the main job's until 2026-12-06, as the variants before were run;
#: the main job's have been "match" and "fcn10+sensor+past" since)
#: the filter's ego motion with KITTI's OXTS step errors (dstenv.sensing.odometry;
#: docs/kitti-pose-check.json: <= 9 cm along, a growing across-track error, <= 0.05 deg)
_ODOMETRY = {"protocol": {"odometry_along": 0.04, "odometry_drift": 0.01,
                          "odometry_yaw": 0.015}}
#: the main job's ``real_net`` since 2026-12-06 (map-free drives, KITTI's moving rule, the
#: past grid), six seeds: the base of the variants of 2026-12-06 and later
_MAIN = {"map": "match", "moving": "match", "inputs": "fcn10+sensor+past",
         "seeds": [0, 1, 2, 3, 4, 5]}

#: variant -> overrides of the ``cpu`` preset (``real_net``, ``model_kwargs``) and of its
#: drives' pipeline (``data_overrides``, merged into ``data.overrides``); the drives are
#: treated as converted without a map (``real_map=False``), as 0003 is
#: (a variant that does not set ``real_net.moving`` or ``inputs`` has "run" and
#: "fcn10+sensor", the main job's until 2026-12-06, as the variants before were run;
#: the main job's have been "match" and "fcn10+sensor+past" since)
VARIANTS: dict[str, dict[str, Any]] = {
    # the main job's networks before real_net.map: the run's map settings
    "none": {"real_net": {"map": "run"}},
    "betp_skip 1.0": {"real_net": {"map": "run"},
                      "model_kwargs": {"unet-light": {"betp_skip": 1.0}}},
    # real_net.map "match": every simulated drive without a map, as the real ones
    "no map": {"real_net": {"map": "match"}},
    "no map 1000 frames": {"real_net": {"map": "match", "frames": 1000}},
    # off-street parking lots (dstenv.sim.lots): cars parked 10-30 m from the road
    "no map lots 0.2": {"real_net": {"map": "match"},
                         "data_overrides": {"world": {"map": {"lot_prob": 0.2}}}},
    "no map odometry": {"real_net": {"map": "match"}, "data_overrides": _ODOMETRY},
    # the sensor grid of one second earlier as two more input channels
    # (dstenv.data.datasets, inputs "fcn10+sensor+past")
    "no map past": {"real_net": {"map": "match", "inputs": "fcn10+sensor+past"}},
    # three more seeds of each (the seed spread on one drive is wide)
    "no map seeds 3-5": {"real_net": {"map": "match", "seeds": [3, 4, 5]}},
    "no map past seeds 3-5": {"real_net": {"map": "match", "inputs": "fcn10+sensor+past",
                                           "seeds": [3, 4, 5]}},
    # both: simulated DST with OXTS-like motion errors (moving evidence on static edges,
    # as KITTI's parked cars have) and the past grid that tells them apart
    "no map past odometry": {"real_net": {"map": "match", "inputs": "fcn10+sensor+past",
                                          "seeds": [0, 1, 2, 3, 4, 5]},
                             "data_overrides": _ODOMETRY},
    # the full median-frequency class weights (the paper's eq. 2) instead of their root
    "no map wp 1.0": {"real_net": {"map": "match"}, "train": {"weight_power": 1.0}},
    # cars as a body on wheels for the 3-D LIDAR (dstenv.sensing.carshape)
    "no map car shape": {"real_net": {"map": "match"},
                         "data_overrides": {"lidar": {"hdl64": {"vehicle_shape": "car"}}}},
    # agents labelled moving by KITTI's rule (10 cm a 0.1 s frame: 1 m/s) instead of the
    # simulator's 0.1 m/s (real_net.moving "match", the main job's since 2026-12-06)
    "no map kitti moving": {"real_net": {"map": "match", "moving": "match",
                                         "seeds": [0, 1, 2, 3, 4, 5]}},
    "no map past kitti moving": {"real_net": _MAIN},
    # six fresh seeds of the same (2026-12-07: the confirmation of the seed choice by
    # the simulated validation drives' static/moving confusion, docs/seed_choice.py)
    "no map past kitti moving seeds 6-11": {"real_net": {**_MAIN, "seeds": [6, 7, 8, 9, 10, 11]}},
    # six more (2026-12-07: the confirmation of "calibrated + free", docs/calibrated_free.py)
    "no map past kitti moving seeds 12-17": {"real_net": {**_MAIN,
                                                          "seeds": [12, 13, 14, 15, 16, 17]}},
    # the same trained twice as long (10 epochs)
    "no map past kitti moving 10 epochs": {"real_net": {**_MAIN, "epochs": 10}},
    # the same with each training sample mirrored left-right at random (train.flip)
    "no map past kitti moving flip": {"real_net": _MAIN, "train": {"flip": 0.5}},
    # the same on twice the simulated drives (1200 frames; four seeds, for time)
    "no map past kitti moving 1200 frames": {"real_net": {**_MAIN, "frames": 1200,
                                                          "seeds": [0, 1, 2, 3]}},
    # the same with KITTI's OXTS-like ego-motion errors in the drives' filter (moving
    # evidence on the rims of parked cars, as 0003's have)
    "no map past kitti moving odometry": {"real_net": _MAIN, "data_overrides": _ODOMETRY},
    # the same with flatter class weights (the root of the root of the median-frequency
    # weights): less pull towards the rare moving class, whose cars the networks draw wide
    "no map past kitti moving wp 0.25": {"real_net": _MAIN, "train": {"weight_power": 0.25}},
    # the same with logits on top of DST's log BetP (betp_skip): the network corrects
    # DST's decision rather than replacing it
    "no map past kitti moving betp_skip": {"real_net": _MAIN,
                                           "model_kwargs": {"unet-light": {"betp_skip": 1.0}}},
}


def main() -> None:
    from dstenv.data import ShardDataset
    from dstenv.data.manifest import load_manifest
    from dstenv.segment.benchmark import run_benchmark
    from dstenv.segment.presets import preset_config
    from dstenv.segment.real import convert_sequences, start_scores
    from dstenv.segment.shardindex import split_index

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kitti", required=True, help="KITTI tracking root (training/...)")
    ap.add_argument("--sequences", default="0003")
    ap.add_argument("--work", required=True, type=Path, help="data and checkpoints")
    ap.add_argument("--out", required=True, type=Path, help="JSON results")
    ap.add_argument("--variants", default=",".join(VARIANTS),
                    help=f"comma-separated subset of: {', '.join(VARIANTS)}")
    ap.add_argument("--val-frames", type=int, default=10)
    ap.add_argument("--val-from", type=int, default=0,
                    help="first choosing frame (frames val-from .. val-from + val-frames - 1; "
                         "keep them before --from-step)")
    ap.add_argument("--from-step", type=int, default=20)
    args = ap.parse_args()
    assert not any("," in v for v in VARIANTS), "a variant name holds the list separator"
    names = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = [v for v in names if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"--variants: unknown {unknown}; choose from {list(VARIANTS)}")

    kdata = args.work / "kitti"
    convert_sequences(args.kitti, args.sequences.split(","), None, kdata)
    manifest = load_manifest(kdata)
    ds = ShardDataset(kdata, split="test", inputs="fcn10")
    index, _ = split_index(ds.files)
    val = [k for k, fr in enumerate(index)
           if args.val_from <= fr["step"] < args.val_from + args.val_frames]
    if args.val_from + args.val_frames > args.from_step:
        raise SystemExit("--val-from/--val-frames: the choosing frames reach the scored ones")
    rows: dict[str, Any] = {}
    timings: dict[str, float] = {}
    resumed = []
    for name in names:
        var = {k: v for k, v in VARIANTS[name].items() if k != "data_overrides"}
        var["real_net"] = {"moving": "run", "inputs": "fcn10+sensor", **var.get("real_net", {})}
        cfg = preset_config("cpu", var)
        extra = VARIANTS[name].get("data_overrides", {})
        cfg["data"]["overrides"] = _merged(cfg["data"]["overrides"], extra)
        if any((args.work / "nets" / _slug(name)).glob("models/*/best.pt")):
            resumed.append(name)  # its timing is then the resume's, not the training's
        t = time.perf_counter()
        ckpts = _train(cfg, manifest, args.work, name)
        timings[name] = time.perf_counter() - t
        vals = start_scores(ckpts, ds, val)
        cfg_s = {"models": [], "device": "cpu", "examples": 1,
                 "score_from_step": args.from_step,
                 "tune": {"enabled": False}, "complete": {"enabled": False}}
        res = run_benchmark(cfg_s, args.work / "scores" / _slug(name),
                            data_dir=kdata, progress=False, log=lambda m: None,
                            checkpoints=list(ckpts.items()))
        for label, row in res["segmenters"].items():
            key = label if row["kind"] != "learned" else f"{name}: {label}"
            iou = row["visible"]["iou"]
            rows[key] = {"val_miou": round(vals[label], 3) if label in vals else None,
                         "static": round(iou["static"], 3), "moving": round(iou["moving"], 3),
                         "miou": round(row["visible"]["miou"], 3)}
            if label in ckpts:  # what the simulated validation drives said of it
                rows[key]["sim_val_miou"] = _sim_val(ckpts[label])
        print(f"{name}: {timings[name]:.0f} s", flush=True)
    out = {"command": "python docs/real_net_variants.py " + shlex.join(sys.argv[1:]),
           "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "selection": f"mIoU over labelled cells of frames {args.val_from}-"
                        f"{args.val_from + args.val_frames - 1}",
           "sim_val_miou": "best mIoU on the simulated validation drives during training",
           "scored": f"visible cells, frames {args.from_step}-", "variants": VARIANTS,
           "rows": rows, "timings_s": {k: round(v, 1) for k, v in timings.items()},
           "resumed": resumed}
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    for k, v in rows.items():
        print(f"{k:55s} val {v['val_miou']} sim val {v.get('sim_val_miou')} static "
              f"{v['static']:.3f} moving {v['moving']:.3f} mIoU {v['miou']:.3f}")


def _sim_val(path: Path) -> float | None:
    """The best validation mIoU on the simulated drives in ``path``'s training history
    (the epoch ``best.pt`` holds), or ``None`` without validation."""
    from dstenv.segment.checkpoint import load_checkpoint

    done = [m for m in load_checkpoint(path)["history"]["val_miou"] if m is not None]
    return round(max(done), 3) if done else None


def _merged(base: dict, over: dict) -> dict:
    """``base`` with ``over`` merged in, section by section (copies)."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _merged(out.get(k, {}), v) if isinstance(v, dict) else v
    return out


def _slug(name: str) -> str:
    """A variant's folder name."""
    return re.sub(r"[^A-Za-z0-9.]+", "_", name)


def _train(cfg, manifest, work, name):
    """Train one variant's networks; variants with the same ``real_net`` map and frames
    share the frames (copied from the first one generated: generation resumes on a
    complete copy)."""
    import shutil

    from dstenv.segment.realnet import real_moving_speed, train_real_networks

    out = work / "nets" / _slug(name)
    extra = _slug(json.dumps(cfg["data"]["overrides"], sort_keys=True))
    rn = cfg["real_net"]
    data = work / "data" / f"{rn['map']}-{rn['frames']}-{rn['moving']}-{extra}"
    if data.is_dir() and not (out / "data").exists():
        out.mkdir(parents=True, exist_ok=True)
        shutil.copytree(data, out / "data")
    ckpts, _ = train_real_networks({"config": cfg}, tuple(manifest["grid_shape"]),
                                   float(manifest["cell_size"]), out, log=lambda m: None,
                                   real_map=False, real_moving=real_moving_speed(manifest))
    if not data.is_dir():
        shutil.copytree(out / "data", data)
    return ckpts


if __name__ == "__main__":
    main()
