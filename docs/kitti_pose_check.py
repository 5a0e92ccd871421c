"""Do KITTI's OXTS poses register consecutive scans? (docs/realism.md, "OXTS pose noise")

For every pair of consecutive converted frames, the occupied cells of the sensor grid
at t-1 (3-40 m from the ego, not labelled ``moving``) are moved into the ego frame of t
by the stored poses' relative motion plus a correction ``(ex, ey, eyaw)``, and scored by
their mean distance (bilinear in a distance transform, capped at 1 m) to the occupied
cells of t. The correction is searched on a grid (+-0.5 m in 0.05 m steps, +-0.5 deg in
0.1 deg steps). On a simulated drive, whose poses are exact, the same search gives the
method's floor: whatever it "corrects" there is the grid's sampling, not pose error::

    dstenv kitti convert --root /work/shared/data/kitti-tracking --sequences 0003 \\
        --stride 1 --warmup 0 --out /tmp/k
    dstenv generate --scenario dense --frames 400 --out /tmp/s --stride 1 --warmup 10 \\
        --episode-length 50 --grid 256 --cell-size 0.33 --set lidar.model=hdl64 \\
        --set gis.source=none --split test --seed 5
    python docs/kitti_pose_check.py --kitti /tmp/k --sim /tmp/s --out docs/kitti-pose-check.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

_STEPS = np.round(np.arange(-0.5, 0.5001, 0.05), 3)  # [m]
_YAWS = np.deg2rad(np.round(np.arange(-0.5, 0.5001, 0.1), 3))  # [rad]


def _pairs(path: Path):
    """``(sensor t-1, sensor t, labels t-1, relative motion)`` of consecutive steps."""
    import h5py

    from dstenv.grid import relative_pose

    with h5py.File(path, "r") as f:
        s, lab, pose = f["sensor"][:], f["labels"][:], f["ego_pose"][:]
        step, seed = f["step"][:], f["seed"][:]
    for k in range(1, len(s)):
        if step[k] == step[k - 1] + 1 and seed[k] == seed[k - 1]:
            yield s[k - 1], s[k], lab[k - 1], relative_pose(pose[k - 1], pose[k])


def _check(prev, cur, lab_prev, motion, spec) -> dict[str, float]:
    from scipy.ndimage import distance_transform_edt, map_coordinates

    from dstenv.dst import CLASSES, SensorState

    occ = int(SensorState.OCCUPIED)
    x, y = spec.cell_centers()
    r = np.hypot(x, y)
    m = (prev == occ) & (lab_prev != CLASSES.index("moving")) & (r > 3) & (r < 40)
    px, py = x[m], y[m]
    dist = distance_transform_edt(cur != occ) * spec.cell_size
    i0, j0 = spec.ego_cell
    dx, dy, dyaw = motion

    def cost(ex: float, ey: float, eyaw: float) -> float:
        a = dyaw + eyaw
        c, s = np.cos(a), np.sin(a)
        qx = c * (px - dx - ex) + s * (py - dy - ey)
        qy = -s * (px - dx - ex) + c * (py - dy - ey)
        rows, cols = i0 - qx / spec.cell_size, j0 - qy / spec.cell_size
        d = map_coordinates(dist, [rows, cols], order=1, mode="constant", cval=1.0)
        return float(np.minimum(d, 1.0).mean())

    base = cost(0.0, 0.0, 0.0)
    best = min((cost(ex, ey, ew), ex, ey, ew) for ex in _STEPS for ey in _STEPS for ew in _YAWS)
    return {"points": int(m.sum()), "cost": base, "best_cost": best[0],
            "ex": float(best[1]), "ey": float(best[2]), "eyaw_deg": float(np.rad2deg(best[3])),
            "motion_m": float(np.hypot(dx, dy))}


def _summary(rows: list[dict[str, float]]) -> dict[str, float]:
    a = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    return {"pairs": len(rows),
            "median_abs_ex_m": float(np.median(np.abs(a["ex"]))),
            "median_abs_ey_m": float(np.median(np.abs(a["ey"]))),
            "median_abs_eyaw_deg": float(np.median(np.abs(a["eyaw_deg"]))),
            "share_shift_over_0.1m": float(np.mean(np.hypot(a["ex"], a["ey"]) > 0.1 + 1e-9)),
            "mean_cost_m": float(a["cost"].mean()),
            "mean_best_cost_m": float(a["best_cost"].mean())}


def main() -> None:
    from dstenv.data.manifest import load_manifest
    from dstenv.grid import GridSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kitti", required=True, type=Path, help="dstenv kitti convert output")
    ap.add_argument("--sim", required=True, type=Path, help="simulated shards at stride 1")
    ap.add_argument("--sim-pairs", type=int, default=120)
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args()
    out: dict = {"command": "python docs/kitti_pose_check.py --kitti "
                            f"{args.kitti} --sim {args.sim} --out {args.out}",
                 "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    for name, root, limit in (("kitti", args.kitti, None), ("sim", args.sim, args.sim_pairs)):
        man = load_manifest(root)
        spec = GridSpec(*man["grid_shape"], float(man["cell_size"]))
        rows = []
        for shard in sorted(root.rglob("*.h5")):
            for pair in _pairs(shard):
                rows.append(_check(*pair, spec))
                if limit and len(rows) >= limit:
                    break
            if limit and len(rows) >= limit:
                break
        out[name] = {"summary": _summary(rows), "pairs": rows}
        print(name, json.dumps(out[name]["summary"]))
    args.out.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
