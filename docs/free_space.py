"""``dst-free`` (docs/benchmark.md): what "no obstacle where the current sweep saw free
space" does on simulated drives and on KITTI, for DST and for networks.

1. Simulated: ``--sim-drives`` validation drives (never test maps) of the ``cpu``
   preset's data (the ``dense`` city, 3-D LIDAR, 128 x 128 cells of 0.33 m, a quarter
   of the drives without a map, 6 s drives scored at 1-5 s), replayed and scored
   by :func:`dstenv.segment.score.score`: ``dst`` and ``dst-free`` over observed and
   visible cells, and how many labelled building / static / moving cells the sweep saw
   free (what the rule would get wrong).
2. KITTI (``--kitti-data``: a ``dstenv kitti convert`` directory, e.g. the main job's
   ``OUT/real/kitti``; ``--checkpoints``: networks, e.g. the main job's ``kitti-labels``
   ``best.pt``): ``dst``, ``dst-free`` and each network with and without the same rule,
   over visible cells of the frames from ``--from-step`` on::

    python docs/free_space.py --out docs/free-space.json \\
        --kitti-data OUT/real/kitti --checkpoints OUT/real/models/unet-light/seed*/best.pt

Prints the IoUs and writes them as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dstenv.dst.frame import CLASSES
from dstenv.segment.segmenters import DSTFreeSegmenter, DSTSegmenter, Segmenter, free_space_veto


class WithVeto(Segmenter):
    """A network, then :func:`free_space_veto` with the sweep its input carries."""

    def __init__(self, inner: Any) -> None:
        self.inner, self.inputs = inner, inner.inputs
        self.name, self.label = inner.name, f"{inner.label} + free"

    def predict(self, x: torch.Tensor) -> torch.Tensor:
        return free_space_veto(self.inner.predict(x), x[:, :5], x[:, 10] > 0.5)


def _ious(scores: Any, scope: str) -> dict[str, dict[str, float | None]]:
    from dstenv.segment.stats import iou_batch, miou_batch

    out = {}
    for label, conf in scores.confusion.items():
        cm = conf[scope].sum(0)
        iou = iou_batch(cm)
        out[label] = {c: (None if not np.isfinite(v) else round(float(v), 4))
                      for c, v in zip(CLASSES, iou)}
        out[label]["miou"] = round(float(miou_batch(cm)), 4)
    return out


def simulated(n: int) -> dict[str, Any]:
    from dstenv.data.sampling import scenario_config, split_of_seed
    from dstenv.dst import SensorState
    from dstenv.segment.presets import preset_config
    from dstenv.segment.replay import generation_params, record_episodes
    from dstenv.segment.score import score

    d = preset_config("cpu")["data"]
    over = {"grid": {"height": d["grid"], "width": d["grid"]}, **d["overrides"]}
    cfg = scenario_config(d["scenario"], over)
    seeds = [s for s in range(10**6) if split_of_seed(s) == "val"][:n]
    steps = list(range(d["warmup"], d["episode_length"], d["stride"]))
    eps = record_episodes(cfg, {(s, 0): steps for s in seeds})
    gen = generation_params(cfg)
    res = score([DSTSegmenter(gen, "dst", "dst (default)"), DSTFreeSegmenter(gen)], eps, gen)
    seen_free = {}
    for c in ("building", "static", "moving"):
        k = CLASSES.index(c)
        lab = [(ep.labels == k) & ep.visible for ep in eps]
        free = [ep.sensor[ep.steps] == SensorState.FREE for ep in eps]
        seen_free[c] = [int(sum((a & f).sum() for a, f in zip(lab, free))),
                        int(sum(a.sum() for a in lab))]
    return {"drives": len(eps), "map_seeds": seeds, "steps": steps,
            "observed": _ious(res, "observed"), "visible": _ious(res, "visible"),
            "labelled_cells_seen_free_of_visible": seen_free}


def kitti(data: Path, checkpoints: list[Path], from_steps: list[int]) -> dict[str, Any]:
    from dstenv.data import ShardDataset
    from dstenv.segment.evaluate import load_checkpoints
    from dstenv.segment.plan import split_drives
    from dstenv.segment.score import score

    ds = ShardDataset(data, split="test")
    out: dict[str, Any] = {"data": str(data), "checkpoints": [str(c) for c in checkpoints]}
    for first in from_steps:
        drives = split_drives(ds, True, False, lambda m: None, from_step=first)
        gen = drives.generation_params
        nets = load_checkpoints(checkpoints, drives.channels) if checkpoints else []
        for net, path in zip(nets, checkpoints):
            net.label = f"{path.parent.name}/{path.name}"
        segs: list[Segmenter] = [DSTSegmenter(gen, "dst", "dst (default)"),
                                 DSTFreeSegmenter(gen)]
        for net in nets:
            segs += [net, WithVeto(net)]
        res = score(segs, drives.episodes, gen)
        out[f"from_step_{first}"] = {"frames": int(res.frames.sum()),
                                     "visible": _ious(res, "visible")}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim-drives", type=int, default=16)
    ap.add_argument("--kitti-data", type=Path)
    ap.add_argument("--checkpoints", type=Path, nargs="*", default=[])
    ap.add_argument("--from-steps", type=int, nargs="*", default=[10, 20],
                    help="score frames from each of these source steps on (10: frames "
                         "10-39 as selected on; 20: the main job's scored frames 20-39)")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    res: dict[str, Any] = {"command": "python docs/free_space.py " + " ".join(sys.argv[1:]),
                           "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if args.sim_drives:
        res["simulated"] = simulated(args.sim_drives)
        for sc in ("observed", "visible"):
            for label, v in res["simulated"][sc].items():
                print(f"sim {sc:8s} {label:14s} " + " ".join(
                    f"{c} {v[c]}" for c in ("building", "static", "moving", "miou")))
        print("sim labelled cells seen free / visible:",
              res["simulated"]["labelled_cells_seen_free_of_visible"])
    if args.kitti_data:
        res["kitti"] = kitti(args.kitti_data, args.checkpoints, args.from_steps)
        for key, part in res["kitti"].items():
            if not key.startswith("from_step"):
                continue
            for label, v in part["visible"].items():
                print(f"kitti {key} {label:40s} static {v['static']} moving {v['moving']} "
                      f"mIoU {v['miou']}")
    if args.out:
        args.out.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
