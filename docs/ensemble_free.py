"""Ensembles of three sim-only networks on KITTI, with the decision rule chosen on the
simulated drives (``docs/preregistration-ensemble.md``, written before this ran).

For every ``real_net`` work folder (``docs/real_net_variants.py --work W``:
``W/nets/VARIANT`` holds ``data/`` and ``models/seedN/best.pt``), the seeds are taken
three at a time in seed order; each triple becomes one
:class:`~dstenv.segment.segmenters.EnsembleSegmenter` (the mean of the three networks'
logits) whose static/moving offset is calibrated on the folder's simulated **validation**
split exactly as a single network's (:func:`dstenv.segment.decide.calibrate_offset`),
then the free-space rule. Scored on KITTI (``--kitti-data``: a ``dstenv kitti convert``
folder; frames from ``--from-step`` on, visible cells) beside its members under the same
rule (``calibrated + free``) and ``dst`` / ``dst-free``; a row meets the sim-only goal when
static and moving are each >= 0.10 IoU over pure DST::

    python docs/ensemble_free.py --kitti-data runs/rnv-km/kitti \\
        --nets runs/rnv-km/nets/no_map_past_kitti_moving \\
               runs/rnv-km/nets/no_map_past_kitti_moving_seeds_6_11 \\
               runs/rnv-km/nets/no_map_past_kitti_moving_seeds_12_17 \\
        --out docs/ensemble-free.json
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
from calibrated_free import goal_met, kitti_ious  # noqa: E402
from seed_choice import nets_args, seed_networks  # noqa: E402

SIZE = 3


def _mean(values: Any) -> float:
    return round(float(np.mean(list(values))), 4)


def main() -> None:
    from dstenv.data import ShardDataset
    from dstenv.segment.decide import calibrate_offset
    from dstenv.segment.results import MARGIN_REAL
    from dstenv.segment.segmenters import EnsembleSegmenter

    args = nets_args(__doc__)
    groups: list[dict[str, Any]] = []
    segs: list[Any] = []
    for folder in args.nets:
        nets = seed_networks(folder)
        if len(nets) % SIZE:
            raise SystemExit(f"--nets {folder}: {len(nets)} seeds, not a multiple of {SIZE}")
        val = ShardDataset(folder / "data", split="val", inputs=nets[0].inputs, labels="kitti")
        for k in range(0, len(nets), SIZE):
            members = nets[k:k + SIZE]
            seeds = [m.label.rsplit("/seed", 1)[1] for m in members]
            ens = EnsembleSegmenter(members, label=f"{folder.name}/ensemble of seeds "
                                                   f"{', '.join(seeds)}")
            off, conf = calibrate_offset(ens, val)
            ens.decision = {"moving_offset": off, "free_veto": True}
            group = {"ensemble": ens.label, "folder": folder.name, "moving_offset": off,
                     "sim_val_confusion": round(float(conf.min()), 4), "members": []}
            for m in members:
                m_off, _ = calibrate_offset(m, val)
                s = copy.copy(m)
                s.decision = {"moving_offset": m_off, "free_veto": True}
                segs.append(s)
                group["members"].append({"network": m.label, "moving_offset": m_off})
            segs.append(ens)
            groups.append(group)
            print(f"{ens.label}: offset {off:+.2f} (members "
                  f"{', '.join(format(g['moving_offset'], '+.2f') for g in group['members'])})",
                  flush=True)
    ious = kitti_ious(args.kitti_data, segs, args.from_step)
    dst = ious["dst"]

    def scored(label: str) -> dict[str, Any]:
        r = ious[label]
        return {**r, "goal_met": goal_met(dst, r)}

    for g in groups:
        g["kitti"] = scored(g["ensemble"])
        for m in g["members"]:
            m["kitti"] = scored(m["network"])
    summary = {
        "ensembles_meeting_goal": sum(g["kitti"]["goal_met"] for g in groups),
        "ensembles": len(groups),
        "members_meeting_goal": sum(m["kitti"]["goal_met"] for g in groups for m in g["members"]),
        "members": sum(len(g["members"]) for g in groups),
        **{f"mean_{c}": {"ensembles": _mean(g["kitti"][c] for g in groups),
                          "members": _mean(m["kitti"][c] for g in groups for m in g["members"])}
           for c in ("static", "moving")},
        "ensembles_moving_at_least_dst_free": sum(g["kitti"]["moving"] >= ious["dst-free"]["moving"]
                                                  for g in groups),
    }
    for g in groups:
        k = g["kitti"]
        print(f"{g['ensemble']:55s} offset {g['moving_offset']:+.2f}  "
              f"{k['static']:.3f}/{k['moving']:.3f}{'*' if k['goal_met'] else ''}   members " +
              "  ".join(f"{m['kitti']['static']:.3f}/{m['kitti']['moving']:.3f}"
                        f"{'*' if m['kitti']['goal_met'] else ''}" for m in g["members"]))
    print(f"dst {dst}, dst-free {ious['dst-free']}")
    print(json.dumps(summary, indent=1))
    if args.out:
        args.out.write_text(json.dumps({
            "command": "python docs/ensemble_free.py " + " ".join(sys.argv[1:]),
            "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "preregistration": "docs/preregistration-ensemble.md",
            "kitti_scope": f"frames from step {args.from_step} on, visible cells",
            "margin": MARGIN_REAL, "dst": dst, "dst_free": ious["dst-free"],
            "summary": summary, "ensembles": groups}, indent=1) + "\n")


if __name__ == "__main__":
    main()
