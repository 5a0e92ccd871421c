"""Fixtures: the shared real KITTI sample (skipped when absent) and a synthetic
sequence in the official layout whose every number is known.

Synthetic world (x east, y north; the ego's Velodyne drives east at 10 m/s)::

    frame k (10 Hz): ego Velodyne at (k, 0), yaw 0
    track 0 "Car" moving: centre (8 + 1.5 k, -4), 4 x 1.8 x 1.5 m, yaw 0 (15 m/s)
    track 1 "Car" parked: centre (15, 6), 4 x 1.8 x 1.5 m, yaw 0
    an unlabelled pole at (25, -10) covered by a DontCare image box
    flat ground at z = -1.73 m (Velodyne frame), rings every 0.5 m out to 45 m
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from shared_data import SHARED_DATA

FIXTURES = Path(__file__).resolve().parent / "fixtures"
SHARED = SHARED_DATA / "kitti-tracking"
SENSOR_Z = -1.73
CAR = (4.0, 1.8, 1.5)  # length, width, height [m]
POLE = (25.0, -10.0, 0.4, 2.0)  # x, y, side, height [m]
LAT0, LON0 = 49.0, 8.4
ER = 6378137.0


def moving_centre(k: int) -> tuple[float, float]:
    return (8.0 + 1.5 * k, -4.0)


PARKED = (15.0, 6.0)


def _box_points(cx: float, cy: float, length: float, width: float, height: float) -> np.ndarray:
    """Points on the four sides and the roof of an axis-aligned box (Velodyne frame)."""
    pts = []
    zs = np.arange(SENSOR_Z + 0.35, SENSOR_Z + height + 1e-9, 0.1)
    # 2.5 cm apart along the sides: denser than the 0.2 deg first-hit bins (a real
    # HDL-64E samples every 0.09 deg)
    for x in np.arange(cx - length / 2, cx + length / 2 + 1e-9, 0.025):
        for y in (cy - width / 2, cy + width / 2):
            pts += [(x, y, z) for z in zs]
    for y in np.arange(cy - width / 2, cy + width / 2 + 1e-9, 0.025):
        for x in (cx - length / 2, cx + length / 2):
            pts += [(x, y, z) for z in zs]
    return np.array(pts)


def _scan(k: int) -> np.ndarray:
    r, a = np.meshgrid(np.arange(3.0, 45.0, 0.5), np.deg2rad(np.arange(0.0, 360.0, 0.5)))
    ground = np.stack([r.ravel() * np.cos(a.ravel()), r.ravel() * np.sin(a.ravel()),
                       np.full(r.size, SENSOR_Z)], axis=1)
    objs = [(*moving_centre(k), CAR[0], CAR[1]), (*PARKED, CAR[0], CAR[1]),
            (POLE[0], POLE[1], POLE[2], POLE[2])]
    keep = np.ones(len(ground), bool)
    parts = []
    for cx, cy, length, width in objs:
        cx -= k  # world -> Velodyne frame (the ego is at (k, 0), yaw 0)
        inside = (np.abs(ground[:, 0] - cx) < length / 2) & (np.abs(ground[:, 1] - cy) < width / 2)
        keep &= ~inside
        height = POLE[3] if length == POLE[2] else CAR[2]
        parts.append(_box_points(cx, cy, length, width, height))
    pts = np.concatenate([ground[keep], *parts])
    return np.concatenate([pts, np.full((len(pts), 1), 0.5)], axis=1).astype(np.float32)


def _project(xyz: np.ndarray) -> np.ndarray:
    """Pixel coordinates with the fixture calibration (``calib_colons.txt``)."""
    cam = np.stack([-xyz[:, 1], -xyz[:, 2] - 0.08, xyz[:, 0] - 0.27], axis=1)
    return np.stack([(700 * cam[:, 0] + 600 * cam[:, 2] + 45) / cam[:, 2],
                     (700 * cam[:, 1] + 180 * cam[:, 2]) / cam[:, 2]], axis=1)


def _label_row(k: int, track: int, cx: float, cy: float) -> str:
    length, width, height = CAR
    # bottom-face centre in the camera frame: (-y, -z - 0.08, x - 0.27); ry = -pi/2 - yaw
    loc = (-cy, -SENSOR_Z - 0.08, cx - 0.27)
    return (f"{k} {track} Car 0 0 0.0 500.0 150.0 700.0 250.0 {height} {width} {length} "
            f"{loc[0]:.6f} {loc[1]:.6f} {loc[2]:.6f} {-np.pi / 2:.6f}")


def make_sequence(root: Path, n_frames: int = 6, seq: str = "0001") -> Path:
    """Write the synthetic sequence under ``root/training``; returns ``root``."""
    split = root / "training"
    (split / "velodyne" / seq).mkdir(parents=True)
    for d in ("label_02", "calib", "oxts"):
        (split / d).mkdir()
    (split / "calib" / f"{seq}.txt").write_text((FIXTURES / "calib_colons.txt").read_text())
    scale = np.cos(np.deg2rad(LAT0))
    rows, labels = [], []
    for k in range(n_frames):
        _scan(k).tofile(split / "velodyne" / seq / f"{k:06d}.bin")
        lon = LON0 + np.rad2deg(k * 1.0 / (scale * ER))  # 1 m east per frame
        rows.append(" ".join([f"{LAT0:.10f}", f"{lon:.10f}", "110.0", "0", "0", "0"] +
                             ["0"] * 19 + ["0.1", "0.1", "4", "8", "4"]))
        mx, my = moving_centre(k)
        labels.append(_label_row(k, 0, mx - k, my))
        labels.append(_label_row(k, 1, PARKED[0] - k, PARKED[1]))
        px, py, side, height = POLE
        corners = np.array([[px - k + dx, py + dy, z] for dx in (-side / 2, side / 2)
                            for dy in (-side / 2, side / 2) for z in (SENSOR_Z, SENSOR_Z + height)])
        uv = _project(corners)
        labels.append(f"{k} -1 DontCare -1 -1 -10 {uv[:, 0].min():.2f} {uv[:, 1].min():.2f} "
                      f"{uv[:, 0].max():.2f} {uv[:, 1].max():.2f} -1000 -1000 -1000 -10 -1 -1 -1")
    (split / "oxts" / f"{seq}.txt").write_text("\n".join(rows) + "\n")
    (split / "label_02" / f"{seq}.txt").write_text("\n".join(labels) + "\n")
    return root


@pytest.fixture
def tiny_root(tmp_path: Path) -> Path:
    """A 6-frame synthetic sequence ``0001`` in the official layout."""
    return make_sequence(tmp_path / "kitti")


@pytest.fixture(scope="session")
def real_root() -> Path:
    """The shared real sample (sequence 0003, frames 0-39), or skip."""
    if not (SHARED / "training" / "velodyne" / "0003").is_dir():
        pytest.skip(f"real KITTI sample absent ({SHARED.resolve()}); set DSTENV_SHARED_DATA "
                    "to a folder holding kitti-tracking/ (README, Set-up)")
    return SHARED
