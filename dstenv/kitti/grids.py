"""Ego-centred label grids of one KITTI frame (axes of :mod:`dstenv.grid`).

Sensor grid
    Made by :func:`dstenv.sensing.cloud.cloud_sensor_grid`, the road shared with
    the simulated 3-D LIDAR (ground removal, one ray per used point).

Label grid (KITTI has 3-D boxes but no road or building labels)
    Class indices follow :data:`dstenv.dst.CLASSES`; cells nobody can label are
    :data:`dstenv.frame.IGNORE_INDEX` (excluded from losses and metrics). In order,
    later steps overwriting earlier ones:

    1. everything starts as ignore;
    2. inside the left camera's horizontal field of view (the only area KITTI
       annotates; objects behind or beside the car are never labelled):
       with a map, cells with a GIS class take it (road -> navigable,
       intermediate -> non_navigable, building -> building); without a map cell
       (or without any map), cells the LIDAR saw **free** become ``navigable``
       when ``free_label == "navigable"`` (the default: "observed free ground",
       the only free-space truth KITTI offers; it includes sidewalks and
       verges, so navigable vs non_navigable scores are not meaningful without
       a map) or stay ignored with ``free_label == "ignore"``. Occupied and
       unseen cells without a map class stay ignored (walls, poles, trees:
       the class is unknown);
    3. ``DontCare`` regions -> ignore: the cells of obstacle points that project
       inside a ``DontCare`` image box (there is no 3-D extent), dilated;
    4. labelled boxes -> ``static``, then ``moving`` (moving wins on overlap),
       everywhere (also outside the field of view), by cell centre inside the
       footprint, at least the centre cell of each box.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_dilation

from dstenv.dst import CLASSES, SensorState
from dstenv.frame import IGNORE_INDEX
from dstenv.grid import GridSpec
from dstenv.kitti.objects import Boxes
from dstenv.kitti.readers import Calibration
from dstenv.sensing.labels import MAP_TO_CLASS
from dstenv.sim.types import MapClass

__all__ = [
    "FREE_LABELS",
    "project_to_image",
    "camera_fov",
    "box_mask",
    "dontcare_cells",
    "label_grid",
    "kitti_convention",
]

FREE_LABELS: tuple[str, ...] = ("navigable", "ignore")
_NAV, _STATIC, _MOVING = (CLASSES.index(c) for c in ("navigable", "static", "moving"))


def project_to_image(xyz: np.ndarray, calib: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """Project Velodyne points into the left colour image.

    Args:
        xyz: ``(P, 3) float`` Velodyne points.

    Returns:
        ``(uv, depth)``: ``(P, 2) float64`` pixel coordinates and ``(P,) float64``
        depth along the camera axis [m] (``uv`` is meaningless where depth <= 0).
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    hom = np.concatenate([xyz, np.ones((len(xyz), 1))], axis=1)
    q = hom @ (calib.P2 @ calib.velo_to_rect).T  # (P, 3)
    depth = q[:, 2]
    safe = np.where(np.abs(depth) > 1e-9, depth, 1e-9)
    return q[:, :2] / safe[:, None], depth


def camera_fov(
    calib: Calibration, spec: GridSpec, image_width: int = 1242, ground_z: float = -1.7
) -> np.ndarray:
    """Cells inside the left camera's horizontal field of view.

    Args:
        calib: the sequence calibration.
        spec: grid geometry.
        image_width: image width [px] (1242 for most KITTI sequences).
        ground_z: height of the projected cell centres in the Velodyne frame [m].

    Returns:
        ``(H, W) bool``.
    """
    x, y = spec.cell_centers()
    xyz = np.stack([x.ravel(), y.ravel(), np.full(x.size, ground_z)], axis=1)
    uv, depth = project_to_image(xyz, calib)
    inside = (depth > 0.5) & (uv[:, 0] >= 0) & (uv[:, 0] < image_width)
    return inside.reshape(spec.shape)


def box_mask(boxes: Boxes, spec: GridSpec) -> np.ndarray:
    """Which cells each box covers (cell centre inside the footprint, and the
    centre cell always).

    Returns:
        ``(K, H, W) bool``.
    """
    out = np.zeros((len(boxes), *spec.shape), dtype=bool)
    xc, yc = spec.cell_centers()
    c = spec.cell_size
    for k in range(len(boxes)):
        cx, cy = boxes.centre[k, :2]
        radius = 0.5 * np.hypot(boxes.length[k], boxes.width[k]) + c
        (i_lo, j_lo), (i_hi, j_hi) = (
            np.asarray(spec.to_cell(cx + radius, cy + radius)),
            np.asarray(spec.to_cell(cx - radius, cy - radius)),
        )
        i_lo, j_lo = max(int(i_lo), 0), max(int(j_lo), 0)
        i_hi, j_hi = min(int(i_hi) + 1, spec.height), min(int(j_hi) + 1, spec.width)
        if i_lo < i_hi and j_lo < j_hi:
            dx = xc[i_lo:i_hi, j_lo:j_hi] - cx
            dy = yc[i_lo:i_hi, j_lo:j_hi] - cy
            cs, sn = np.cos(boxes.yaw[k]), np.sin(boxes.yaw[k])
            along, across = cs * dx + sn * dy, -sn * dx + cs * dy
            out[k, i_lo:i_hi, j_lo:j_hi] = (np.abs(along) <= boxes.length[k] / 2) & (
                np.abs(across) <= boxes.width[k] / 2
            )
        i, j = spec.to_cell(cx, cy)
        if spec.inside(i, j):
            out[k, i, j] = True
    return out


def dontcare_cells(
    points: np.ndarray, obstacle: np.ndarray, bboxes: np.ndarray, calib: Calibration,
    spec: GridSpec, dilation: int = 1,
) -> np.ndarray:
    """Cells of ``DontCare`` regions: obstacle points whose image projection falls
    inside a ``DontCare`` box, dilated by ``dilation`` cells.

    Args:
        points: ``(P, 3+) float`` Velodyne points; ``obstacle``: ``(P,) bool``.
        bboxes: ``(D, 4) float`` image boxes (left, top, right, bottom) [px].

    Returns:
        ``(H, W) bool``.
    """
    out = np.zeros(spec.shape, dtype=bool)
    if len(bboxes) == 0:
        return out
    xyz = np.asarray(points, dtype=np.float64)[obstacle, :3]
    uv, depth = project_to_image(xyz, calib)
    b = np.asarray(bboxes, dtype=np.float64)
    u, v = uv[:, :1], uv[:, 1:]
    within = (u >= b[:, 0]) & (u <= b[:, 2]) & (v >= b[:, 1]) & (v <= b[:, 3])  # (P, D)
    sel = within.any(axis=1) & (depth > 0)
    i, j = spec.to_cell(xyz[sel, 0], xyz[sel, 1])
    keep = spec.inside(i, j)
    out[i[keep], j[keep]] = True
    if dilation > 0 and out.any():
        out = binary_dilation(out, iterations=dilation)
    return out


def label_grid(
    boxes: Boxes,
    moving: np.ndarray,
    sensor: np.ndarray,
    fov: np.ndarray,
    dontcare: np.ndarray,
    spec: GridSpec,
    gis: np.ndarray | None = None,
    free_label: str = "navigable",
) -> np.ndarray:
    """Label grid of one frame (rules in the module docstring).

    Args:
        boxes: the frame's boxes (Velodyne frame); ``moving``: ``(K,) bool``.
        sensor: ``(H, W) uint8`` sensor grid of the frame.
        fov: ``(H, W) bool`` from :func:`camera_fov`.
        dontcare: ``(H, W) bool`` from :func:`dontcare_cells`.
        spec: grid geometry.
        gis: ``(H, W) uint8`` GIS grid, or ``None`` without a map.
        free_label: ``"navigable"`` or ``"ignore"`` for seen-free cells without a map class.

    Returns:
        ``(H, W) uint8`` class indices or :data:`dstenv.frame.IGNORE_INDEX`.
    """
    if free_label not in FREE_LABELS:
        raise ValueError(f"free_label must be one of {', '.join(FREE_LABELS)}, got {free_label!r}")
    out = np.full(spec.shape, IGNORE_INDEX, dtype=np.uint8)
    if free_label == "navigable":
        out[fov & (sensor == SensorState.FREE)] = _NAV
    if gis is not None:  # the simulator's map -> class table; code 0 means "no map here"
        mapped = fov & (gis != MapClass.NONE)
        out[mapped] = MAP_TO_CLASS[gis[mapped]]
    out[dontcare] = IGNORE_INDEX
    masks = box_mask(boxes, spec)
    moving = np.asarray(moving, dtype=bool)
    if len(boxes):
        out[masks[~moving].any(axis=0)] = _STATIC
        out[masks[moving].any(axis=0)] = _MOVING
    return out


def kitti_convention(labels: np.ndarray, sensor: np.ndarray) -> np.ndarray:
    """Full labels (a simulated frame's) relabelled the way :func:`label_grid` labels a
    KITTI frame without a map: ``static``/``moving`` kept everywhere, other cells the
    LIDAR sees free now ``navigable`` (the ``free_label`` rule), every other cell
    ignored (walls, poles, kerbs, unseen ground: KITTI has no class for them). The
    camera's field of view is not applied: a network trained on it learns from every
    direction.

    Args:
        labels: ``(..., H, W) uint8`` class indices or :data:`IGNORE_INDEX`.
        sensor: ``(..., H, W) uint8`` sensor grid of the same frames.

    Returns:
        ``(..., H, W) uint8``, a new array.
    """
    labels, sensor = np.asarray(labels), np.asarray(sensor)
    if labels.shape != sensor.shape:
        raise ValueError(f"labels {labels.shape} and sensor {sensor.shape} differ")
    out = np.full(labels.shape, IGNORE_INDEX, dtype=np.uint8)
    out[sensor == SensorState.FREE] = _NAV
    obj = (labels == _STATIC) | (labels == _MOVING)
    out[obj] = labels[obj]
    return out
