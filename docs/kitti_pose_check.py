"""Are KITTI's OXTS poses what puts moving evidence on its parked cars? (docs/realism.md)

1. **Registration.** Each scan's obstacle points (the converter's own ground removal,
   3-40 m, points near a box flagged moving dropped) are matched to the next scan's by
   2-D point-to-point ICP (trimmed at 0.5 m, started from the OXTS motion); the
   per-step differences between the ICP motion and the OXTS one are recorded.
2. **Re-conversion.** The sequence is converted again with the ICP motions chained
   from the first pose (same labels: the moving flags still come from the OXTS
   track), and the DST presets, ``dst-tuned`` and the networks of a main job's KITTI
   section are scored on both conversions, visible cells, from step 20 on, as there::

    python docs/kitti_pose_check.py --kitti KITTI \\
        --results runs/cpu33/results.json --work /tmp/pose --out docs/kitti-pose-check.json

``--results`` names the run whose checkpoints and ``dst-tuned`` parameters are used
(without patched poses the conversion here is byte for byte the main job's); about 2
minutes.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def _obstacles(seq, f: int, spec, cfg, moving: np.ndarray) -> np.ndarray:
    """``(N, 2)`` obstacle points of frame ``f`` in its Velodyne frame."""
    from dstenv.sensing.cloud import cloud_sensor_grid

    pts = seq.scan(f)
    obst = cloud_sensor_grid(pts, spec, cfg["ground"], cfg["sensor"])[3]
    p = pts[obst, :2].astype(np.float64)
    r = np.hypot(p[:, 0], p[:, 1])
    p = p[(r > 3) & (r < 40)]
    sel = (seq.boxes.frame == f) & moving
    for c, length, width in zip(seq.boxes.centre[sel], seq.boxes.length[sel],
                                seq.boxes.width[sel], strict=True):
        p = p[np.hypot(p[:, 0] - c[0], p[:, 1] - c[1]) > max(length, width) / 2 + 1.0]
    return p


def _icp(src: np.ndarray, dst: np.ndarray, init: tuple[float, float, float],
         iters: int = 30, trim: float = 0.5) -> tuple[float, float, float, float]:
    """Rigid ``q = R(th) p + t`` taking ``src`` onto ``dst``: ``(tx, ty, th, median
    residual of the kept pairs)``."""
    from scipy.spatial import cKDTree

    tx, ty, th = init
    tree = cKDTree(dst)
    for _ in range(iters):
        c, s = np.cos(th), np.sin(th)
        d, i = tree.query(src @ np.array([[c, s], [-s, c]]) + [tx, ty])
        m = d < trim
        a, b = src[m], dst[i[m]]
        ma, mb = a.mean(0), b.mean(0)
        h = (a - ma).T @ (b - mb)
        th = float(np.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1]))
        c, s = np.cos(th), np.sin(th)
        tx, ty = mb - np.array([[c, -s], [s, c]]) @ ma
    return float(tx), float(ty), th, float(np.median(d[m]))


def _rot(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def icp_motions(seq, spec, cfg) -> list[dict[str, float]]:
    """Per step ``f``: the OXTS and ICP motions of frame ``f`` in frame ``f - 1``."""
    from dstenv.grid import relative_pose

    moving = seq.moving(cfg["labels"]["rule"], cfg["labels"]["threshold"],
                        cfg["labels"]["window"])
    poses = seq.trajectory.poses
    prev = _obstacles(seq, 0, spec, cfg, moving)
    rows = []
    for f in range(1, seq.n_frames):
        cur = _obstacles(seq, f, spec, cfg, moving)
        dx, dy, dyaw = relative_pose(poses[f - 1], poses[f])
        # a world-static point p of frame f-1 is R(-dyaw) (p - d) in frame f
        t0 = -_rot(-dyaw) @ np.array([dx, dy])
        tx, ty, th, res = _icp(prev, cur, (t0[0], t0[1], -dyaw))
        d = -_rot(-th) @ np.array([tx, ty])
        rows.append({"frame": f, "oxts": [dx, dy, dyaw], "icp": [float(d[0]), float(d[1]), -th],
                     "residual_m": res})
        prev = cur
    return rows


def chain(first: np.ndarray, rows: list[dict[str, float]]) -> np.ndarray:
    """``(N, 3)`` world poses from ``first`` and the rows' ICP motions."""
    out = [np.asarray(first, np.float64)]
    for r in rows:
        x, y, yaw = out[-1]
        dx, dy, dyaw = r["icp"]
        off = _rot(yaw) @ np.array([dx, dy])
        out.append(np.array([x + off[0], y + off[1], yaw + dyaw]))
    return np.stack(out)


def use_icp_poses(seq) -> None:
    """Replace ``seq``'s OXTS poses, in place, by the chain of ICP scan-to-scan motions
    from its first pose (the grid and ground settings of a frame-by-frame conversion)."""
    from dstenv.grid import GridSpec
    from dstenv.kitti.sequence import kitti_config

    cfg = kitti_config({"stride": 1, "warmup": 0})
    seq.trajectory.poses[:] = chain(seq.trajectory.poses[0].copy(),
                                    icp_motions(seq, GridSpec(**cfg["grid"]), cfg))


def _convert(seq, cfg, out: Path) -> None:
    from dstenv.data.manifest import shard_entry, write_manifest
    from dstenv.data.shards import ShardWriter
    from dstenv.kitti.sequence import convert_sequence

    if (out / "manifest.json").is_file():
        return
    path = out / "test" / f"kitti-{seq.name}.h5"
    attrs = {"config": cfg, "seed": int(seq.name), "split": "test", "source": "kitti",
             "sequence": seq.name, "map": "none"}
    with ShardWriter(path, attrs) as w:
        for frame in convert_sequence(seq, cfg):
            w.add(frame)
    write_manifest(out, [shard_entry(out, path)], {"command": "docs/kitti_pose_check.py"})


def main() -> None:
    from dstenv.grid import GridSpec
    from dstenv.kitti.sequence import KittiSequence, kitti_config
    from dstenv.segment.benchmark import run_benchmark

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kitti", required=True, help="KITTI tracking root")
    ap.add_argument("--sequence", default="0003")
    ap.add_argument("--results", required=True, type=Path,
                    help="results.json of a main job with a KITTI section")
    ap.add_argument("--work", required=True, type=Path)
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args()
    run = json.loads(args.results.read_text())
    kitti = run["kitti"]
    cfg = kitti_config({"stride": 1, "warmup": 0})  # as the main job converts
    spec = GridSpec(**cfg["grid"])
    seq = KittiSequence(args.kitti, args.sequence)
    rows = icp_motions(seq, spec, cfg)
    diff = np.array([np.subtract(r["icp"], r["oxts"]) for r in rows])
    oxts = seq.trajectory.poses.copy()
    data = {"oxts": args.work / "kitti-oxts", "icp": args.work / "kitti-icp"}
    _convert(seq, cfg, data["oxts"])  # byte-identical to the main job's conversion
    seq.trajectory.poses[:] = chain(oxts[0], rows)
    _convert(seq, cfg, data["icp"])

    # every network of the run's KITTI table, the fine-tuned one included
    ckpts = [(k, v["describe"]["checkpoint"]) for k, v in kitti["segmenters"].items()
             if v["kind"] == "learned"]
    scores = {}
    for name, root in data.items():
        bcfg = {"models": [], "device": "cpu", "examples": 1, "score_from_step": 20,
                "tune": {"enabled": True,
                         "params": run["segmenters"]["dst-tuned"]["describe"]["params"]},
                "complete": {"enabled": False}}
        res = run_benchmark(bcfg, args.work / f"scores-{name}", data_dir=root, progress=False,
                            log=lambda m: None, checkpoints=ckpts)
        scores[name] = {k: {c: round(v["visible"]["iou"][c], 3) for c in ("static", "moving")}
                        | {"miou": round(v["visible"]["miou"], 3)}
                        for k, v in res["segmenters"].items()}
    out = {"command": f"python docs/kitti_pose_check.py --kitti {args.kitti} --results "
                      f"{args.results} --work {args.work} --out {args.out}",
           "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "sequence": seq.name,
           "icp_minus_oxts": {
               "along_m": {"median_abs": float(np.median(np.abs(diff[:, 0]))),
                           "max_abs": float(np.abs(diff[:, 0]).max())},
               "across_m": {"median_abs": float(np.median(np.abs(diff[:, 1]))),
                            "max_abs": float(np.abs(diff[:, 1]).max())},
               "yaw_deg": {"median_abs": float(np.rad2deg(np.median(np.abs(diff[:, 2])))),
                           "max_abs": float(np.rad2deg(np.abs(diff[:, 2]).max()))},
               "median_residual_m": float(np.median([r["residual_m"] for r in rows]))},
           "max_chained_offset_m": float(np.hypot(*(seq.trajectory.poses[:, :2]
                                                    - oxts[:, :2]).T).max()),
           "steps": rows, "visible_iou": scores}
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out["icp_minus_oxts"], indent=1))
    for k in scores["oxts"]:
        a, b = scores["oxts"][k], scores["icp"][k]
        print(f"{k:45s} oxts static {a['static']:.3f} moving {a['moving']:.3f} | "
              f"icp static {b['static']:.3f} moving {b['moving']:.3f}")


if __name__ == "__main__":
    main()
