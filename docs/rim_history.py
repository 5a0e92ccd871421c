"""Why was a parked car's rim cell seen free before it was occupied?

Issue 14, docs/realism.md ("Parked cars' rims"): of KITTI 0003's static rim cells
occupied at t (30-42 m), 32 % were seen free in one of the ten sweeps before; the
simulator gives 5-9 %. This script takes each such event (a rim cell occupied at t whose
cell in sweep t-k, by the filter's nearest-cell warp, was free) and asks the scan of
t-k what cleared it: the nearest obstacle point within the ray's blocking window
(``rays.block_window_deg``) of the cell's azimuth, and how far beyond the cell's centre
it lay (``margin``). A margin under a cell means the car's own surface ended the ray
just behind the cell (the rim only partly covered); a large margin or none means that
sweep had no obstacle return of the car in that direction at all. It also says whether
the cell of t-k lay inside that sweep's own static label::

    python docs/rim_history.py --kitti-root KITTI \\
        --drives 10 --out docs/rim-history.json [--lidar '{"hdl64": {...}}'] [--icp]
"""

from __future__ import annotations

import argparse
import json
import shlex
import math
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ego_speed import FAST, STATIC, _interior  # noqa: E402

from dstenv.dst.reference import source_cells  # noqa: E402
from dstenv.grid import GridSpec, relative_pose  # noqa: E402
from dstenv.sensing.cloud import cloud_sensor_grid  # noqa: E402

_FREE, _OCC = 1, 2
HISTORY = 10
BAND = (30.0, 42.0)
#: margin bins [m] of the blocking obstacle beyond the free cell's centre
MARGINS = (0.0, 0.33, 1.0, 3.0, np.inf)


def _margin_bin(m: float) -> str:
    if not np.isfinite(m):
        return "no obstacle in the window"
    if m < 0:
        return "obstacle nearer than the cell"
    for lo, hi in zip(MARGINS[:-1], MARGINS[1:]):
        if lo <= m < hi:
            return f"{lo:g}-{hi:g} m beyond"
    return "?"


class Events:
    """Counts of the rim events and their explanations."""

    def __init__(self) -> None:
        self.occupied = 0  # rim cells occupied at t in the band
        self.with_free = 0  # of them, free in one of the HISTORY sweeps before
        self.events: Counter = Counter()  # (margin bin) over every free (cell, k)
        self.in_label: Counter = Counter()  # free cell of t-k inside t-k's static label?
        self.lowest: list[float] = []  # height above ground of the blocking point
        self.ks: Counter = Counter()

    def table(self) -> dict:
        n = sum(self.events.values())
        return {"rim_cells_occupied_t": self.occupied,
                "free_in_last_10": round(self.with_free / max(self.occupied, 1), 3),
                "free_events": n,
                "margin": {k: round(v / max(n, 1), 3) for k, v in sorted(self.events.items())},
                "cell_in_static_label_at_t_minus_k": round(self.in_label[True] / max(n, 1), 3),
                "k": {int(k): v for k, v in sorted(self.ks.items())},
                "blocker_height_median": (round(float(np.median(self.lowest)), 3)
                                          if self.lowest else None)}


def _add(ev: Events, frames: list, scans: list, spec: GridSpec, window_deg: float) -> None:
    x, y = spec.cell_centers()
    dist = np.hypot(x, y)
    half = math.radians(window_deg) / 2
    for t in range(1, len(frames)):
        f = frames[t]
        static = f.labels == STATIC
        rim = static & ~_interior(static) & (dist >= BAND[0]) & (dist < BAND[1])
        cells = np.argwhere(rim & (f.sensor == _OCC))
        if not len(cells):
            continue
        ev.occupied += len(cells)
        any_free = np.zeros(len(cells), bool)
        for k in range(1, min(HISTORY, t) + 1):
            p = frames[t - k]
            si, sj, ok = source_cells(spec.shape, spec.cell_size,
                                      relative_pose(p.ego_pose, f.ego_pose))
            a, b = si[cells[:, 0], cells[:, 1]], sj[cells[:, 0], cells[:, 1]]
            good = ok[cells[:, 0], cells[:, 1]]
            free = good & (p.sensor[a, b] == _FREE)
            any_free |= free
            xyz, obstacle, height = scans[t - k]
            ox, oy = xyz[obstacle, 0], xyz[obstacle, 1]
            o_az, o_r = np.arctan2(oy, ox), np.hypot(ox, oy)
            o_h = height[obstacle]
            for c in np.flatnonzero(free):
                cx, cy = x[a[c], b[c]], y[a[c], b[c]]
                r_c, az = math.hypot(cx, cy), math.atan2(cy, cx)
                d = np.abs((o_az - az + np.pi) % (2 * np.pi) - np.pi)
                near = d <= half
                if near.any():
                    j = np.flatnonzero(near)[np.argmin(o_r[near])]
                    m = float(o_r[j] - r_c)
                    ev.lowest.append(float(o_h[j]))
                else:
                    m = np.inf
                ev.events[_margin_bin(m)] += 1
                ev.in_label[bool(p.labels[a[c], b[c]] == STATIC)] += 1
                ev.ks[k] += 1
        ev.with_free += int(any_free.sum())


def kitti(root: Path, sequence: str, icp: bool = False) -> dict:
    from dstenv.kitti.sequence import KittiSequence, convert_sequence, kitti_config

    seq = KittiSequence(root, sequence)
    cfg = kitti_config({"stride": 1, "warmup": 0})
    spec = GridSpec(**cfg["grid"])
    if icp:  # the scans registered to each other (docs/kitti_pose_check.py)
        from kitti_pose_check import use_icp_poses

        use_icp_poses(seq)
    frames = list(convert_sequence(seq, {"stride": 1, "warmup": 0}))
    scans = []
    for fr in frames:
        pts = seq.scan(fr.step)
        _, _, _, obstacle, height = cloud_sensor_grid(pts, spec, cfg["ground"], cfg["sensor"])
        scans.append((pts[:, :3].astype(np.float64), obstacle, height))
    ev = Events()
    _add(ev, frames, scans, spec, float(cfg["sensor"]["block_window_deg"]))
    return ev.table()


def sim(drives: int, lidar: dict | None, size: int = 256) -> dict:
    from dstenv.config import merge_config
    from dstenv.data.sampling import scenario_config
    from dstenv.pipeline import Pipeline

    over = {"grid": {"height": size, "width": size}, "lidar": {"model": "hdl64"},
            "gis": {"no_map_prob": 1.0}, "world": {"traffic": {"parked_density": 0.3}}}
    if lidar:
        over["lidar"] = {**over["lidar"], **lidar}
    pipe = Pipeline(merge_config(scenario_config("dense", over), FAST, "fast"))
    ev = Events()
    for seed in range(drives):
        frames, scans = [], []
        f = pipe.reset(seed)
        for t in range(120):
            if t:
                f = pipe.step(None)
            if pipe.world.ego_speed < 9.0:  # KITTI 0003's speed (9-15 m/s) only
                if len(frames) > 1:
                    _add(ev, frames, scans, pipe.spec, _window(pipe))
                frames, scans = [], []
                continue
            cloud = pipe.sweep
            _, _, _, obstacle, height = cloud_sensor_grid(
                cloud.points, pipe.spec, cloud.config["ground"], cloud.config["rays"],
                offset=(float(cloud.mount[0]), float(cloud.mount[1])))
            xyz = cloud.points[:, :3].astype(np.float64)
            xyz[:, 0] += cloud.mount[0]
            xyz[:, 1] += cloud.mount[1]
            frames.append(f)
            scans.append((xyz, obstacle, height))
        if len(frames) > 1:
            _add(ev, frames, scans, pipe.spec, _window(pipe))
    return ev.table()


def _window(pipe) -> float:
    return float(pipe.sweep.config["rays"]["block_window_deg"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kitti-root", help="omit to measure the simulator only")
    ap.add_argument("--sequence", default="0003")
    ap.add_argument("--drives", type=int, default=10)
    ap.add_argument("--lidar", default="", help="JSON overrides of the lidar section")
    ap.add_argument("--icp", action="store_true",
                    help="KITTI with ICP scan-to-scan poses instead of OXTS")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    res = {"command": "python docs/rim_history.py " + shlex.join(sys.argv[1:]),
           "band_m": list(BAND)}
    if args.kitti_root:
        res["kitti"] = kitti(Path(args.kitti_root), args.sequence, args.icp)
    if args.drives:
        res["sim"] = sim(args.drives, json.loads(args.lidar) if args.lidar else None)
    Path(args.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
