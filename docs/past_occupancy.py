"""Is "occupied a second ago at the same place" a cue that tells parked from moving?

Issue 14: on KITTI 0003 the networks call the two parked cars moving, because DST puts
moving evidence on their rims (docs/realism.md, "Parked cars' rims"). A cue that
needs no evidence model: the sensor grid of ``--past`` sweeps earlier, moved into the
ego frame of t by the filter's nearest-cell warp. A static object's visible cells
were occupied there too (if seen then); a moving one's were not. This script gives,
for the visible static and moving cells at t (the KITTI sample converted with every
scan, frames ``--past``..39; simulated ``dense`` drives without a map at KITTI's
speed, the ``fast`` variant of ``docs/ego_speed.py``, 256 x 256 cells), the share
whose warped past cell was occupied, free and unknown, and pure DST's argmax::

    python docs/past_occupancy.py --kitti-root KITTI \\
        --drives 10 --out docs/past-occupancy.json

If the cue separates the classes in both sources alike, an input channel with it (the
past sensor grid) is worth building for the networks that read real drives.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from edge_flicker import warped  # noqa: E402
from ego_speed import FAST, MOVING, STATIC  # noqa: E402

from dstenv.grid import GridSpec  # noqa: E402

_UNK, _FREE, _OCC = 0, 1, 2
#: [m] distance bands of the cells
BANDS = ((0.0, 21.0), (21.0, 42.0), (0.0, np.inf))


class Tally:
    def __init__(self) -> None:
        self.n = defaultdict(lambda: np.zeros(3 + 5, np.int64))  # past state, DST argmax

    def add(self, key: str, past: np.ndarray, argmax: np.ndarray) -> None:
        self.n[key][:3] += np.bincount(past, minlength=3)[:3]
        self.n[key][3:] += np.bincount(argmax, minlength=5)[:5]

    def table(self) -> dict:
        out = {}
        for key in sorted(self.n):
            c = self.n[key]
            tot = int(c[:3].sum())
            out[key] = {"cells": tot,
                        "past_occupied": round(c[_OCC] / tot, 3) if tot else None,
                        "past_free": round(c[_FREE] / tot, 3) if tot else None,
                        "past_unknown": round(c[_UNK] / tot, 3) if tot else None,
                        "dst_says_moving": round(c[3 + MOVING] / tot, 3) if tot else None,
                        "dst_says_static": round(c[3 + STATIC] / tot, 3) if tot else None}
        return out


def _add(tally: Tally, prefix: str, frames: list, past: int, spec: GridSpec) -> None:
    x, y = spec.cell_centers()
    dist = np.hypot(x, y)
    for t in range(past, len(frames)):
        f, p = frames[t], frames[t - past]
        prev = warped(p.sensor, p.ego_pose, f.ego_pose, spec)
        vis = f.sensor != _UNK
        argmax = np.argmax(f.pignistic, axis=0)
        for cls, name in ((STATIC, "static"), (MOVING, "moving")):
            m = vis & (f.labels == cls)
            for lo, hi in BANDS:
                sel = m & (dist >= lo) & (dist < hi)
                if sel.any():
                    band = "all" if hi == np.inf else f"{lo:g}-{hi:g} m"
                    tally.add(f"{prefix} {band} {name}", prev[sel], argmax[sel])


def kitti(root: Path, sequence: str, past: int) -> dict:
    from dstenv.kitti.sequence import KittiSequence, convert_sequence

    seq = KittiSequence(root, sequence)
    frames = list(convert_sequence(seq, {"stride": 1, "warmup": 0}))
    tally = Tally()
    _add(tally, "kitti", frames, past, GridSpec(256, 256, 0.33))
    return tally.table()


def sim(drives: int, past: int) -> dict:
    from dstenv.config import merge_config
    from dstenv.data.sampling import scenario_config
    from dstenv.pipeline import Pipeline

    over = {"grid": {"height": 256, "width": 256}, "lidar": {"model": "hdl64"},
            "gis": {"no_map_prob": 1.0}, "world": {"traffic": {"parked_density": 0.3}}}
    pipe = Pipeline(merge_config(scenario_config("dense", over), FAST, "fast"))
    tally = Tally()
    for seed in range(drives):
        frames = [pipe.reset(seed)] + [pipe.step(None) for _ in range(79)]
        _add(tally, "sim", frames[10:], past, pipe.spec)
    return tally.table()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kitti-root", help="omit to measure the simulator only")
    ap.add_argument("--sequence", default="0003")
    ap.add_argument("--drives", type=int, default=10)
    ap.add_argument("--past", type=int, default=10, help="sweeps back (10: one second)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    res = {"command": "python docs/past_occupancy.py " + shlex.join(sys.argv[1:])}
    if args.kitti_root:
        res["kitti"] = kitti(Path(args.kitti_root), args.sequence, args.past)
    if args.drives:
        res["sim"] = sim(args.drives, args.past)
    Path(args.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
