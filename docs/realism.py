"""Measure how real the simulated street looks to a segmenter (issue 12).

Writes the figures of ``docs/realism.md`` to a JSON file::

    python docs/realism.py --out docs/realism.json          # ~10 min on 2 busy cores
    python docs/realism.py --quick --out /tmp/realism.json   # a smoke run

The figures are those of the scenarios as shipped by the dstenv that is imported;
"before" is the same script run on the code before issue 12 (see docs/realism.md:
``PYTHONPATH=<old checkout> python docs/realism.py --out docs/realism-before.json``),
``--clean`` puts the clean scenario's overrides under each scenario (an ablation):

* ``grid``: the ``default`` scenario at 256 x 256 cells of 0.33 m: unknown / free /
  occupied shares of the sensor grid by distance from the ego, and the class shares
  of the labels (the figures of `the project's realism targets`);
* ``bench``: the ``dense`` scenario at the benchmark's settings (128 x 128, a frame
  every 10 steps, 12 drives):
  - ``map_only``: a segmenter that reads only the GIS grid (``MAP_TO_CLASS[gis]``),
    mIoU and IoU per class over all cells (0.594 before, issue 12);
  - ``kerb_rule``: static IoU of the no-learning rule "cells where DST's argmax is
    static or moving, or the sensor is occupied, grown by 1.5 m inside the kerb strip
    (non-road, non-building GIS cells within 2.2 m of a GIS road cell) are static"
    (0.46 before, issue 12), next to DST's own static IoU;
  - ``dst_confusion``: DST argmax vs labels on visible cells; the ``non_navigable``
    row shows the static / moving false alarms on clutter;
  - class shares of the labels.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import numpy as np
from scipy import ndimage

from dstenv.config import merge_config
from dstenv.scenario_files import load_scenario
from dstenv.dst import CLASSES, SensorState
from dstenv.pipeline import Pipeline, default_config
from dstenv.sensing.labels import MAP_TO_CLASS
from dstenv.sim.types import MapClass

STATIC, MOVING = CLASSES.index("static"), CLASSES.index("moving")
BANDS = ((0.0, 1e9, "all cells"), (0.0, 10.0, "0-10 m"), (10.0, 20.0, "10-20 m"),
         (20.0, 42.0, "20-42 m"))


def scenario(name: str, clean: bool, grid: int) -> dict[str, Any]:
    """The pipeline config of a shipped scenario; ``clean``: defaults, then the clean
    scenario's overrides, then the scenario's own (its traffic and layout kept)."""
    base = default_config()
    if clean:
        base = merge_config(base, load_scenario("clean"), "clean")
    cfg = load_scenario(name, base)
    return merge_config(cfg, {"grid": {"height": grid, "width": grid}}, "grid")


def frames(cfg: dict[str, Any], drives: int, steps: int, stride: int, seed0: int):
    """Frames every ``stride`` steps (from step ``stride`` on) of ``drives`` drives."""
    p = Pipeline(cfg)
    for d in range(drives):
        p.reset(seed0 + d)
        for t in range(1, steps + 1):
            f = p.step()
            if t % stride == 0:
                yield f


def confusion(pred: np.ndarray, true: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    n = len(CLASSES)
    p, t = pred.ravel(), true.ravel()
    if mask is not None:
        p, t = p[mask.ravel()], t[mask.ravel()]
    return np.bincount(t.astype(np.int64) * n + p, minlength=n * n).reshape(n, n)


def iou(cm: np.ndarray) -> np.ndarray:
    tp = np.diag(cm).astype(float)
    den = cm.sum(0) + cm.sum(1) - tp
    return np.where(den > 0, tp / np.maximum(den, 1), np.nan)


def kerb_rule(f, cell: float) -> np.ndarray:
    """The no-learning static rule of issue 12 on one frame: ``(H, W) bool``."""
    road = f.gis == MapClass.ROAD
    strip = (~road) & (f.gis != MapClass.BUILDING) & \
        (ndimage.distance_transform_edt(~road) * cell <= 2.2)
    arg = f.pignistic.argmax(0)
    hits = (arg == STATIC) | (arg == MOVING) | (f.sensor == SensorState.OCCUPIED)
    r = int(round(1.5 / cell))
    disk = np.hypot(*np.mgrid[-r:r + 1, -r:r + 1]) <= r
    return ndimage.binary_dilation(hits, disk) & strip


def grid_figures(cfg, drives, steps, stride, seed0) -> dict[str, Any]:
    h = cfg["grid"]["height"]
    c = cfg["grid"]["cell_size"]
    ii, jj = np.mgrid[0:h, 0:h]
    dist = np.hypot(ii - h // 2, jj - h // 2) * c
    counts = {name: np.zeros(3) for *_, name in BANDS}
    labels = np.zeros(len(CLASSES))
    n = 0
    for f in frames(cfg, drives, steps, stride, seed0):
        n += 1
        for lo, hi, name in BANDS:
            m = (dist >= lo) & (dist < hi)
            counts[name] += np.bincount(f.sensor[m], minlength=3)
        labels += np.bincount(f.labels.ravel(), minlength=len(CLASSES))
    shares = {name: dict(zip(("unknown", "free", "occupied"), (v / v.sum()).round(4).tolist()))
              for name, v in counts.items()}
    return {"frames": n, "sensor_shares": shares,
            "class_shares": dict(zip(CLASSES, (labels / labels.sum()).round(5).tolist()))}


def bench_figures(cfg, drives, steps, stride, seed0) -> dict[str, Any]:
    c = cfg["grid"]["cell_size"]
    n = len(CLASSES)
    cm_map, cm_dst, cm_vis = (np.zeros((n, n), np.int64) for _ in range(3))
    rule = np.zeros(3, np.int64)  # tp, fp, fn of static
    labels = np.zeros(n)
    frames_n = 0
    for f in frames(cfg, drives, steps, stride, seed0):
        frames_n += 1
        cm_map += confusion(MAP_TO_CLASS[f.gis], f.labels)
        arg = f.pignistic.argmax(0)
        cm_dst += confusion(arg, f.labels)
        cm_vis += confusion(arg, f.labels, f.visible)
        pred = kerb_rule(f, c)
        true = f.labels == STATIC
        rule += [int((pred & true).sum()), int((pred & ~true).sum()), int((~pred & true).sum())]
        labels += np.bincount(f.labels.ravel(), minlength=n)
    map_iou = iou(cm_map)
    row = cm_vis[CLASSES.index("non_navigable")]
    return {
        "frames": frames_n,
        "map_only": {"miou": round(float(np.nanmean(map_iou)), 4),
                     "iou": dict(zip(CLASSES, np.round(map_iou, 4).tolist()))},
        "kerb_rule": {"static_iou": round(rule[0] / max(rule.sum(), 1), 4),
                      "dst_static_iou": round(float(iou(cm_dst)[STATIC]), 4)},
        "dst_confusion_visible": cm_vis.tolist(),
        "dst_non_navigable_predicted": dict(zip(CLASSES, (row / max(row.sum(), 1)).round(4)
                                                .tolist())),
        "class_shares": dict(zip(CLASSES, (labels / labels.sum()).round(5).tolist())),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="JSON file to write")
    ap.add_argument("--quick", action="store_true", help="2 drives per figure (smoke run)")
    ap.add_argument("--clean", action="store_true",
                    help="apply the clean scenario's overrides after the scenario's own")
    args = ap.parse_args(argv)
    q = args.quick
    import dstenv

    out: dict[str, Any] = {
        "command": "python docs/realism.py" + " --quick" * q + " --clean" * args.clean,
        "dstenv": dstenv.__file__, "clean": args.clean}
    t0 = time.time()
    # the realism-targets setting: 256 x 256 cells, 60 frames of the default scenario
    out["grid"] = grid_figures(scenario("default", args.clean, 256), 2 if q else 6, 100, 10, 11)
    print(f"grid: {time.time() - t0:.0f} s", file=sys.stderr)
    # the benchmark setting of issue 12: dense, 128 x 128, a frame every 10 steps, 12 drives
    out["bench"] = bench_figures(scenario("dense", args.clean, 128), 2 if q else 12, 100, 10,
                                 1000)
    print(f"bench: {time.time() - t0:.0f} s", file=sys.stderr)
    if "source" in default_config()["gis"]:
        none = merge_config(scenario("dense", args.clean, 128), {"gis": {"source": "none"}})
        out["bench_no_map"] = {"map_only": bench_figures(none, 2, 100, 10, 1000)["map_only"]}
    with open(args.out, "w") as fh:
        json.dump(out, fh, indent=1)
    b = out["bench"]
    print(f"map-only mIoU {b['map_only']['miou']}, kerb rule static IoU "
          f"{b['kerb_rule']['static_iou']}, DST static IoU {b['kerb_rule']['dst_static_iou']}, "
          f"class shares {b['class_shares']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
