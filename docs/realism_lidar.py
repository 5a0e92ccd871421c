"""Scan and sensor-grid figures of KITTI sequences, real or exported by ``dstenv export-kitti``.

Usage (numbers in docs/realism-lidar.md)::

    python docs/realism_lidar.py ROOT SEQUENCE [ROOT SEQUENCE ...]

Both kinds go through the same code (:func:`dstenv.kitti.sequence.convert_sequence`,
every frame, 256 x 256 cells of 0.33 m), so the figures compare like with like.
"""

from __future__ import annotations

import sys

if __name__ == "__main__" and {"-h", "--help"} & set(sys.argv[1:]):  # usage: the docstring
    print(__doc__)
    raise SystemExit(0)

import sys

import numpy as np

from dstenv.kitti.sequence import KittiSequence, convert_sequence

BANDS = ((0, 10), (10, 20), (20, 42))


def figures(root: str, sequence: str) -> dict[str, object]:
    seq = KittiSequence(root, sequence)
    n_pts, ground, ranges, elev = [], [], [], []
    for f in range(seq.n_frames):
        p = seq.scan(f)
        n_pts.append(len(p))
        ground.append(float((p[:, 2] < -1.4).mean()))
        r = np.hypot(p[:, 0], p[:, 1])
        ranges.append(r)
        elev.append(np.rad2deg(np.arctan2(p[:, 2], r)))
    r = np.concatenate(ranges)
    shares = {b: np.zeros(3) for b in BANDS}
    total = np.zeros(3)
    cfg = {"stride": 1, "warmup": 0}
    for fr in convert_sequence(seq, cfg):
        h, w = fr.sensor.shape
        ii, jj = np.mgrid[:h, :w]
        d = np.hypot(ii - h // 2, jj - w // 2) * 0.33
        total += np.bincount(fr.sensor.ravel(), minlength=3)
        for lo, hi in BANDS:
            sel = (d >= lo) & (d < hi)
            shares[(lo, hi)] += np.bincount(fr.sensor[sel], minlength=3)
    return {
        "frames": seq.n_frames,
        "points per scan (min/median/max)": (min(n_pts), int(np.median(n_pts)), max(n_pts)),
        "share below z = -1.4 m": round(float(np.mean(ground)), 3),
        "elevation 0.5/99.5 % [deg]": tuple(np.round(np.percentile(np.concatenate(elev),
                                                                   [0.5, 99.5]), 1)),
        "range 10/50/90/99 % [m]": tuple(np.round(np.percentile(r, [10, 50, 90, 99]), 1)),
        "share beyond 42 m": round(float((r > 42).mean()), 3),
        "grid unknown/free/occupied (all)": tuple(np.round(total / total.sum(), 3)),
        **{f"grid u/f/o {lo}-{hi} m": tuple(np.round(v / v.sum(), 3))
           for (lo, hi), v in shares.items()},
    }


if __name__ == "__main__":
    args = sys.argv[1:]
    for root, seq in zip(args[::2], args[1::2]):
        print(f"## {root} sequence {seq}")
        for k, v in figures(root, seq).items():
            print(f"{k:36s} {tuple(float(x) for x in v) if isinstance(v, tuple) else v}")
