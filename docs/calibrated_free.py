"""A decision rule chosen on the simulated drives for the sim-only networks on KITTI.

For every seed of one or more ``real_net`` work folders (``docs/real_net_variants.py
--work W``: ``W/nets/VARIANT`` holds ``data/`` and ``models/seedN/best.pt``) this scores,
on KITTI (``--kitti-data``: a ``dstenv kitti convert`` folder; frames from ``--from-step``
on, visible cells, as the main job scores them), four decision rules of the same network
(:mod:`dstenv.segment.decide`):

* ``argmax``: the network as trained;
* ``free``: argmax, then the free-space rule (no obstacle where the sweep saw free);
* ``calibrated``: the static/moving offset with the least static/moving confusion on the
  simulated **validation** drives of its own training data (``data/val``, KITTI's label
  convention, visible cells); no real frame chooses anything;
* ``calibrated + free``: both, the rule preregistered in
  ``docs/preregistration-calibrated-free.md`` before seeds 12-17 were trained;

and whether each meets the sim-only goal (static and moving each >= 0.10 IoU over pure
DST, ``dstenv.segment.results.MARGIN_REAL``), with ``dst-free`` beside them::

    python docs/calibrated_free.py --kitti-data runs/rnv-km/kitti \\
        --nets runs/rnv-km/nets/no_map_past_kitti_moving \\
               runs/rnv-km/nets/no_map_past_kitti_moving_seeds_6_11 \\
               runs/rnv-km/nets/no_map_past_kitti_moving_seeds_12_17 \\
        --out docs/calibrated-free.json
"""

from __future__ import annotations

import copy
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))  # docs/: the work folders' helpers
from seed_choice import nets_args, seed_networks  # noqa: E402

RULES = ("argmax", "free", "calibrated", "calibrated + free")


def goal_met(dst: dict[str, float], r: dict[str, float]) -> bool:
    """The sim-only goal: static and moving IoU each >= ``MARGIN_REAL`` over pure DST."""
    from dstenv.segment.results import MARGIN_REAL

    return all(r[c] - dst[c] >= MARGIN_REAL for c in ("static", "moving"))


def kitti_ious(kdata: Path, segs: list[Any], from_step: int) -> dict[str, dict[str, float]]:
    """Static / moving IoU over visible cells of ``dst``, ``dst-free`` and ``segs``."""
    from dstenv.data import ShardDataset
    from dstenv.dst.frame import CLASSES
    from dstenv.segment.plan import split_drives
    from dstenv.segment.score import score
    from dstenv.segment.segmenters import DSTFreeSegmenter, DSTSegmenter
    from dstenv.segment.stats import iou_batch

    drives = split_drives(ShardDataset(kdata, split="test"), True, False, lambda m: None,
                          from_step=from_step)
    gen = drives.generation_params
    base = [DSTSegmenter(gen, "dst", "dst"), DSTFreeSegmenter(gen)]
    res = score([*base, *segs], drives.episodes, gen)
    out = {}
    for s in [*base, *segs]:
        iou = iou_batch(res.confusion[s.label]["visible"].sum(0))
        out[s.label] = {c: round(float(iou[CLASSES.index(c)]), 4) for c in ("static", "moving")}
    return out


def main() -> None:
    from dstenv.data import ShardDataset
    from dstenv.segment.decide import OFFSETS, calibrate_offset
    from dstenv.segment.results import MARGIN_REAL

    args = nets_args(__doc__)
    rows: list[dict[str, Any]] = []
    segs: list[Any] = []
    for folder in args.nets:
        nets = seed_networks(folder)
        val = ShardDataset(folder / "data", split="val", inputs=nets[0].inputs, labels="kitti")
        for net in nets:
            name = net.label
            off, conf = calibrate_offset(net, val)
            rows.append({"network": name, "folder": folder.name, "moving_offset": off,
                         "sim_val_confusion": {"argmax": round(float(conf[OFFSETS.index(0.0)]), 4),
                                               "calibrated": round(float(conf.min()), 4)}})
            for rule in RULES:
                s = copy.copy(net)
                s.label = f"{name}: {rule}"
                s.decision = (None if rule == "argmax" else
                              {"moving_offset": off if "calibrated" in rule else 0.0,
                               "free_veto": "free" in rule})
                segs.append(s)
            print(f"{name}: offset {off:+.2f}", flush=True)
    ious = kitti_ious(args.kitti_data, segs, args.from_step)
    dst = ious["dst"]

    for row in rows:
        row["kitti"] = {rule: {**ious[f"{row['network']}: {rule}"],
                               "goal_met": goal_met(dst, ious[f"{row['network']}: {rule}"])}
                        for rule in RULES}
    summary = {}
    for rule in RULES:
        k = [r["kitti"][rule] for r in rows]
        summary[rule] = {"seeds_meeting_goal": sum(x["goal_met"] for x in k), "seeds": len(k),
                         "mean_static": round(float(np.mean([x["static"] for x in k])), 4),
                         "mean_moving": round(float(np.mean([x["moving"] for x in k])), 4),
                         "moving_at_least_dst_free": sum(x["moving"] >= ious["dst-free"]["moving"]
                                                         for x in k)}
    for folder in args.nets:
        mine = [r for r in rows if r["folder"] == folder.name]
        summary[folder.name] = {rule: sum(r["kitti"][rule]["goal_met"] for r in mine)
                                for rule in RULES}
    for r in rows:
        print(f"{r['network']:50s} offset {r['moving_offset']:+.2f}  " + "  ".join(
            f"{rule}: {v['static']:.3f}/{v['moving']:.3f}{'*' if v['goal_met'] else ''}"
            for rule, v in r["kitti"].items()))
    print(f"dst {dst}, dst-free {ious['dst-free']}")
    print(json.dumps(summary, indent=1))
    if args.out:
        args.out.write_text(json.dumps({
            "command": "python docs/calibrated_free.py " + " ".join(sys.argv[1:]),
            "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "kitti_scope": f"frames from step {args.from_step} on, visible cells",
            "offsets": list(OFFSETS), "margin": MARGIN_REAL, "dst": dst,
            "dst_free": ious["dst-free"], "summary": summary, "networks": rows},
            indent=1) + "\n")


if __name__ == "__main__":
    main()
