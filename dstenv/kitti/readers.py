"""Readers for the KITTI tracking files: Velodyne scans, labels, calibration, OXTS.

Layout (the official download, ``SSSS`` a 4-digit sequence, ``FFFFFF`` a frame)::

    <root>/training/velodyne/SSSS/FFFFFF.bin   float32 rows (x, y, z, reflectance)
    <root>/training/label_02/SSSS.txt          17 columns per object (devkit readme)
    <root>/training/calib/SSSS.txt             P0..P3, R_rect, Tr_velo_cam, Tr_imu_velo
    <root>/training/oxts/SSSS.txt              30 columns per frame (lat, lon, alt, ...)

``<root>`` may also be the ``training`` folder itself. Every reader raises
:class:`KittiError` with a one-line message naming the file (and line) on bad input.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = [
    "KittiError",
    "OBJECT_TYPES",
    "Labels",
    "Calibration",
    "split_root",
    "velodyne_path",
    "read_velodyne",
    "read_labels",
    "read_calib",
    "read_oxts",
]

#: Object types of the tracking labels, in the devkit's order; index = ``Labels.type``.
OBJECT_TYPES: tuple[str, ...] = (
    "Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc", "DontCare",
    "Person",  # in the tracking labels beside the devkit's list (TrackEval: person sitting)
)
DONTCARE: int = OBJECT_TYPES.index("DontCare")

# Calibration keys and their aliases (the object benchmark spells them differently).
_CALIB_KEYS: dict[str, tuple[tuple[str, ...], int]] = {
    "P2": (("P2",), 12),
    "R_rect": (("R_rect", "R0_rect"), 9),
    "Tr_velo_cam": (("Tr_velo_cam", "Tr_velo_to_cam"), 12),
    "Tr_imu_velo": (("Tr_imu_velo", "Tr_imu_to_velo"), 12),
}


class KittiError(ValueError):
    """Bad or missing KITTI input; the message names the file (and line)."""


@dataclass
class Labels:
    """All objects of one sequence, one entry per label row (structure of arrays).

    Attributes:
        frame: ``(K,) int64`` frame index.
        track: ``(K,) int64`` track id (-1 for ``DontCare``).
        type: ``(K,) int64`` index into :data:`OBJECT_TYPES`.
        bbox: ``(K, 4) float64`` image box (left, top, right, bottom) [px].
        hwl: ``(K, 3) float64`` height, width, length [m].
        location: ``(K, 3) float64`` bottom-face centre, rectified camera frame [m].
        rotation_y: ``(K,) float64`` yaw about the camera y axis [rad].
    """

    frame: np.ndarray
    track: np.ndarray
    type: np.ndarray
    bbox: np.ndarray
    hwl: np.ndarray
    location: np.ndarray
    rotation_y: np.ndarray

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    def select(self, mask: np.ndarray) -> Labels:
        """The rows where ``mask`` (``(K,) bool``) is true."""
        return Labels(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))

    @property
    def is_dontcare(self) -> np.ndarray:
        """``(K,) bool``: rows of type ``DontCare``."""
        return self.type == DONTCARE


@dataclass(frozen=True)
class Calibration:
    """The matrices of ``calib/SSSS.txt`` that the converter needs, as 4x4 or 3x4.

    Attributes:
        P2: ``(3, 4) float64`` projection of the left colour camera (rectified).
        R_rect: ``(4, 4) float64`` rectifying rotation, padded with a 1.
        Tr_velo_cam: ``(4, 4) float64`` Velodyne -> camera 0 (unrectified).
        Tr_imu_velo: ``(4, 4) float64`` IMU (OXTS) -> Velodyne.
    """

    P2: np.ndarray
    R_rect: np.ndarray
    Tr_velo_cam: np.ndarray
    Tr_imu_velo: np.ndarray

    @property
    def velo_to_rect(self) -> np.ndarray:
        """``(4, 4) float64``: Velodyne -> rectified camera (the labels' frame)."""
        return self.R_rect @ self.Tr_velo_cam

    @property
    def rect_to_velo(self) -> np.ndarray:
        """``(4, 4) float64``: rectified camera -> Velodyne."""
        return np.linalg.inv(self.velo_to_rect)


def split_root(root: str | Path) -> Path:
    """The folder holding ``velodyne/``, ``label_02/``...: ``root/training`` or ``root``.

    Raises:
        KittiError: if neither holds a ``velodyne`` folder.
    """
    root = Path(root)
    for cand in (root / "training", root):
        if (cand / "velodyne").is_dir():
            return cand
    raise KittiError(f"{root}: no KITTI tracking data (expected {root}/training/velodyne/ or "
                     f"{root}/velodyne/); point the root at KITTI's training/ folder or the "
                     "one above it")


def velodyne_path(split: Path, sequence: str, frame: int) -> Path:
    """Path of the scan of one frame: ``split/velodyne/SSSS/FFFFFF.bin``."""
    return split / "velodyne" / sequence / f"{frame:06d}.bin"


#: [m] farther than any LIDAR return (the HDL-64E ranges ~120 m): a coordinate beyond
#: this is a damaged scan, not a far point
MAX_COORDINATE = 1000.0


def read_velodyne(path: str | Path) -> np.ndarray:
    """Read one Velodyne scan.

    Returns:
        ``(P, 4) float32`` rows ``(x, y, z, reflectance)``, Velodyne frame
        (x forward, y left, z up) [m].

    Raises:
        KittiError: missing file, a size that is not a whole number of points,
            non-finite or implausibly far coordinates, reflectance outside [0, 1].
    """
    path = Path(path)
    try:
        size = path.stat().st_size
        if size == 0 or size % 16:
            raise KittiError(
                f"{path}: {size} bytes is not a positive multiple of 16 "
                "(4 float32 per point): truncated or not a Velodyne scan"
            )
        raw = np.fromfile(path, dtype="<f4")
    except FileNotFoundError:
        raise KittiError(f"{path}: missing Velodyne scan") from None
    except IsADirectoryError:
        raise KittiError(f"{path}: is a directory, not a Velodyne scan") from None
    except OSError as exc:
        raise KittiError(f"{path}: cannot read: {exc.strerror}") from None
    points = raw.reshape(-1, 4).astype(np.float32, copy=False)
    if not np.isfinite(points[:, :3]).all():
        raise KittiError(f"{path}: non-finite coordinates in the scan")
    far = np.abs(points[:, :3]).max(axis=1) > MAX_COORDINATE
    if far.any():
        k = int(np.argmax(far))
        raise KittiError(f"{path}: point {k} lies {float(np.abs(points[k, :3]).max()):.3g} m "
                         f"from the sensor (an HDL-64E sees {MAX_COORDINATE:g} m at most): a "
                         "damaged scan")
    refl = points[:, 3]
    if not (np.isfinite(refl).all() and refl.min() >= 0.0 and refl.max() <= 1.0):
        raise KittiError(f"{path}: reflectance outside [0, 1] (KITTI stores x, y, z, "
                         "reflectance as 4 float32 a point): not a KITTI Velodyne scan")
    return points


def _read_lines(path: Path, what: str) -> list[str]:
    try:
        return path.read_text(encoding="utf-8-sig").splitlines()  # a BOM is not a key
    except FileNotFoundError:
        raise KittiError(f"{path}: missing {what} file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise KittiError(f"{path}: cannot read {what} file: {exc}") from None


def _floats(tokens: list[str], path: Path, lineno: int) -> np.ndarray:
    try:
        return np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError as exc:
        raise KittiError(f"{path}:{lineno}: not a number ({exc})") from None


def read_labels(path: str | Path) -> Labels:
    """Read ``label_02/SSSS.txt`` (17 columns; an 18th score column is accepted).

    Raises:
        KittiError: missing file, wrong column count, unknown type or non-numbers,
            naming the file and line.
    """
    path = Path(path)
    rows: list[tuple[int, int, int, np.ndarray]] = []
    lines: list[int] = []  # the file line of each row
    seen: dict[tuple[int, int], int] = {}  # (frame, track) -> line
    for lineno, line in enumerate(_read_lines(path, "label"), start=1):
        tok = line.split()
        if not tok:
            continue
        if len(tok) not in (17, 18):
            raise KittiError(f"{path}:{lineno}: expected 17 label columns, got {len(tok)}")
        if tok[2] not in OBJECT_TYPES:
            raise KittiError(
                f"{path}:{lineno}: unknown object type {tok[2]!r}; known: {', '.join(OBJECT_TYPES)}"
            )
        try:
            frame, track = int(tok[0]), int(tok[1])
        except ValueError:
            raise KittiError(f"{path}:{lineno}: frame and track id must be integers") from None
        if frame < 0:
            raise KittiError(f"{path}:{lineno}: negative frame index {frame}")
        if tok[2] != "DontCare":  # DontCare regions carry track -1; objects a track each
            if track < 0:
                raise KittiError(f"{path}:{lineno}: negative track id {track} on a "
                                 f"{tok[2]} (only DontCare rows have -1)")
            if (frame, track) in seen:
                raise KittiError(f"{path}:{lineno}: track {track} appears twice in frame "
                                 f"{frame} (also line {seen[frame, track]})")
            seen[frame, track] = lineno
        rows.append((frame, track, OBJECT_TYPES.index(tok[2]), _floats(tok[3:17], path, lineno)))
        lines.append(lineno)
    vals = np.array([r[3] for r in rows], dtype=np.float64).reshape(-1, 14)
    _check_boxes(path, vals, [r[2] for r in rows], lines)
    return Labels(
        frame=np.array([r[0] for r in rows], dtype=np.int64),
        track=np.array([r[1] for r in rows], dtype=np.int64),
        type=np.array([r[2] for r in rows], dtype=np.int64),
        bbox=vals[:, 3:7].copy(),
        hwl=vals[:, 7:10].copy(),
        location=vals[:, 10:13].copy(),
        rotation_y=vals[:, 13].copy(),
    )


#: plausible extents of a labelled object: height, width, length [m] and distance [m]
_MAX_HWL = (6.0, 6.0, 30.0)
_MAX_DISTANCE = 500.0


def _check_boxes(path: Path, vals: np.ndarray, types: list[int], lines: list[int]) -> None:
    """Reject non-finite or absurd boxes (DontCare rows carry the -1/-1000/-10 fillers);
    ``lines``: each row's line in the file."""
    for i, row in enumerate(vals):
        if not np.isfinite(row).all():
            raise KittiError(f"{path}:{lines[i]}: non-finite value; a corrupt label file")
        if types[i] == DONTCARE:
            continue
        hwl, loc = row[7:10], row[10:13]
        if (hwl <= 0).any() or (hwl > _MAX_HWL).any():
            raise KittiError(f"{path}:{lines[i]}: implausible box size h, w, l = "
                             f"{hwl.tolist()} m (allowed (0, {_MAX_HWL}] m)")
        if np.abs(loc).max() > _MAX_DISTANCE:
            raise KittiError(f"{path}:{lines[i]}: box {loc.tolist()} m away from the "
                             f"camera (more than {_MAX_DISTANCE:g} m)")


#: the farthest two sensors of one car are apart in a calibration [m]
_MAX_MOUNT = 5.0


def _check_rotation(path: Path, name: str, m: np.ndarray) -> None:
    """``m``'s top-left 3x3 block must be a rotation: finite, orthonormal, det +1."""
    r = m[:3, :3]
    if not np.isfinite(m).all():
        raise KittiError(f"{path}: {name} holds non-finite values")
    if not np.allclose(r @ r.T, np.eye(3), atol=2e-2) or not abs(np.linalg.det(r) - 1) < 2e-2:
        raise KittiError(f"{path}: {name} is not a rotation (+ translation); a corrupt or "
                         "hand-edited calibration file")
    if m.shape[1] == 4 and np.abs(m[:3, 3]).max() > _MAX_MOUNT:
        raise KittiError(f"{path}: {name} translates by {m[:3, 3].round(3).tolist()} m, more "
                         f"than {_MAX_MOUNT:g} m between two sensors of one car (translations "
                         "are metres)")


def _pad4(m: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[: m.shape[0], : m.shape[1]] = m
    return out


def read_calib(path: str | Path) -> Calibration:
    """Read ``calib/SSSS.txt``; keys may be written ``P2:`` or ``R_rect`` (with or
    without a colon), and the object benchmark's aliases (``R0_rect``,
    ``Tr_velo_to_cam``, ``Tr_imu_to_velo``) are accepted.

    Raises:
        KittiError: missing file, a required key absent (``P2``, ``R_rect``,
            ``Tr_velo_cam``, ``Tr_imu_velo``) or with the wrong number of values.
    """
    path = Path(path)
    found: dict[str, tuple[np.ndarray, int]] = {}
    for lineno, line in enumerate(_read_lines(path, "calibration"), start=1):
        tok = line.split()
        if not tok:
            continue
        key = tok[0].rstrip(":")
        if len(tok) > 1 and tok[1] == ":":  # "key : values"
            tok = [tok[0], *tok[2:]]
        if key in found:  # two P2 lines: which one is meant cannot be guessed
            raise KittiError(f"{path}:{lineno}: {key} again (first on line {found[key][1]}); "
                             "keep one")
        found[key] = (_floats(tok[1:], path, lineno), lineno)
    mats: dict[str, np.ndarray] = {}
    for name, (aliases, count) in _CALIB_KEYS.items():
        hits = [a for a in aliases if a in found]
        if len(hits) > 1:  # two spellings of one matrix: as two P2 lines, not guessed
            (a, la), (b, lb) = sorted(((h, found[h][1]) for h in hits), key=lambda t: t[1])[:2]
            raise KittiError(f"{path}:{lb}: {b} is {a} of line {la} again (another spelling "
                             "of one matrix); keep one")
        hit = hits[0] if hits else None
        if hit is None:
            raise KittiError(f"{path}: calibration has no {name} (keys found: {', '.join(found)})")
        vals, lineno = found[hit]
        if vals.size != count:
            raise KittiError(f"{path}:{lineno}: {hit} needs {count} values, got {vals.size}")
        mats[name] = vals
    if not np.isfinite(mats["P2"]).all():
        raise KittiError(f"{path}: P2 holds non-finite values")
    for name in ("R_rect", "Tr_velo_cam", "Tr_imu_velo"):
        _check_rotation(path, name, mats[name].reshape(3, -1))
    return Calibration(
        P2=mats["P2"].reshape(3, 4),
        R_rect=_pad4(mats["R_rect"].reshape(3, 3)),
        Tr_velo_cam=_pad4(mats["Tr_velo_cam"].reshape(3, 4)),
        Tr_imu_velo=_pad4(mats["Tr_imu_velo"].reshape(3, 4)),
    )


#: [m] largest plausible move between two OXTS rows (0.1 s apart: 400 km/h)
_MAX_STEP = 11.0


def _ground_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Horizontal distance [m] between two OXTS rows (equirectangular; small steps)."""
    r = 6378137.0
    lat = np.radians(0.5 * (a[0] + b[0]))
    dy = np.radians(b[0] - a[0]) * r
    dx = np.radians(b[1] - a[1]) * r * np.cos(lat)
    return float(np.hypot(dx, dy))


def read_oxts(path: str | Path) -> np.ndarray:
    """Read ``oxts/SSSS.txt``: one row of 30 values per frame.

    Returns:
        ``(N, 30) float64``; columns 0-5 are lat [deg], lon [deg], alt [m],
        roll, pitch, yaw [rad] (yaw 0 = east, counter-clockwise).

    Raises:
        KittiError: missing or empty file, wrong column count, non-numbers,
            latitudes outside [-90, 90], roll or pitch beyond +-pi/2 or yaw beyond
            +-pi (degrees for radians), a jump of more than 11 m between rows.
    """
    path = Path(path)
    rows = []
    for lineno, line in enumerate(_read_lines(path, "OXTS"), start=1):
        tok = line.split()
        if not tok:
            continue
        if len(tok) != 30:
            raise KittiError(f"{path}:{lineno}: expected 30 OXTS columns, got {len(tok)}")
        row = _floats(tok, path, lineno)
        if not np.isfinite(row[:6]).all() or abs(row[0]) >= 90.0:
            raise KittiError(f"{path}:{lineno}: invalid latitude/longitude/attitude")
        if max(abs(row[3]), abs(row[4])) > np.pi / 2 or abs(row[5]) > np.pi + 1e-6:
            raise KittiError(f"{path}:{lineno}: roll, pitch, yaw = {row[3]:g}, {row[4]:g}, "
                             f"{row[5]:g}: outside +-pi/2, +-pi/2, +-pi (OXTS angles are "
                             "radians)")
        if rows:
            jump = _ground_distance(rows[-1], row)
            if jump > _MAX_STEP:
                raise KittiError(
                    f"{path}:{lineno}: position jumps {jump:.0f} m from the previous row "
                    f"(more than {_MAX_STEP:g} m in 0.1 s); a corrupt or concatenated OXTS file")
        rows.append(row)
    if not rows:
        raise KittiError(f"{path}: no OXTS rows")
    return np.stack(rows)
