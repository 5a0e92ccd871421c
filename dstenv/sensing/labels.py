"""Exact ground truth for every cell of the ego grid, occluded cells included.

Classes follow :data:`dstenv.dst.CLASSES`: the map gives ``building`` (BUILDING),
``navigable`` (ROAD) and ``non_navigable`` (INTERMEDIATE, or no map at all); the
footprint of every agent (an oriented box: the cells whose centre lies inside it,
and at least the cell of its centre so a pedestrian never vanishes) is ``moving``
when its speed exceeds the threshold, else ``static``. Where footprints overlap,
``moving`` wins. Street clutter standing on the ground (``WorldMap.obstacles`` with
``z_min <`` :data:`GROUND_CLEARANCE`: poles, trunks, hedges, bins, ...) is
``non_navigable`` with the same footprint rule, under the agents; what hangs above
(tree crowns, sign panels) leaves the ground label as it is.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dstenv.dst import CLASSES, SensorState
from dstenv.grid import GridSpec
from dstenv.sensing.gis import _check_pose, _lookup
from dstenv.sim.types import Agents, MapClass, WorldMap

__all__ = ["label_grid", "visible_mask", "MAP_TO_CLASS", "GROUND_CLEARANCE"]

#: clutter whose bottom is lower than this stands on the ground and is labelled [m]
GROUND_CLEARANCE: float = 0.3

_NAV = CLASSES.index("navigable")
_NONNAV = CLASSES.index("non_navigable")
_BUILDING = CLASSES.index("building")
_STATIC = CLASSES.index("static")
_MOVING = CLASSES.index("moving")

#: ``(4,) uint8``: :class:`MapClass` code -> class index in ``CLASSES``.
MAP_TO_CLASS: np.ndarray = np.zeros(len(MapClass), dtype=np.uint8)
MAP_TO_CLASS[MapClass.NONE] = _NONNAV
MAP_TO_CLASS[MapClass.BUILDING] = _BUILDING
MAP_TO_CLASS[MapClass.ROAD] = _NAV
MAP_TO_CLASS[MapClass.INTERMEDIATE] = _NONNAV
MAP_TO_CLASS.flags.writeable = False
# the same, over every uint8 code; 255 flags codes that are no MapClass
_LUT = np.full(256, 255, dtype=np.uint8)
_LUT[: len(MAP_TO_CLASS)] = MAP_TO_CLASS


def label_grid(
    world_map: WorldMap,
    agents: Agents,
    pose: np.ndarray,
    spec: GridSpec,
    moving_threshold: float = 0.1,
) -> np.ndarray:
    """Ground-truth class of every ego-grid cell.

    Args:
        world_map: the true map.
        agents: the other road users (the ego is not labelled).
        pose: ``(3,)`` ego world pose ``(x [m], y [m], yaw [rad])``.
        spec: grid geometry (:mod:`dstenv.grid`).
        moving_threshold: an agent faster than this is ``moving`` [m/s].

    Returns:
        ``(H, W) uint8`` class indices in :data:`dstenv.dst.CLASSES` order.
    """
    px, py, yaw = _check_pose(pose, "label_grid")
    if not moving_threshold >= 0:
        raise ValueError(f"label_grid: moving_threshold must be >= 0 m/s, got {moving_threshold}")
    raster = np.ascontiguousarray(world_map.raster, dtype=np.uint8)
    out = np.empty(spec.shape, dtype=np.uint8)
    bad = _lookup(raster, float(world_map.origin[0]), float(world_map.origin[1]),
                  float(world_map.resolution), px, py, yaw, float(spec.cell_size), _LUT, out)
    if bad:
        codes = sorted(set(np.unique(raster).tolist()) - set(int(m) for m in MapClass))
        raise ValueError(f"label_grid: the map raster holds codes that are no MapClass: {codes}")
    obs = world_map.obstacles
    if len(obs):
        reach = 0.75 * spec.cell_size * max(spec.shape) + 10.0  # > half diagonal + box size
        rel = obs.xy - (px, py)
        k = np.flatnonzero((obs.z_min < GROUND_CLEARANCE) & (np.abs(rel[:, 0]) < reach)
                           & (np.abs(rel[:, 1]) < reach))
        if len(k):
            c, s = math.cos(yaw), math.sin(yaw)
            _paint_boxes(out, c * rel[k, 0] + s * rel[k, 1], -s * rel[k, 0] + c * rel[k, 1],
                         obs.yaw[k] - yaw, obs.length[k] / 2, obs.width[k] / 2,
                         np.full(len(k), _NONNAV, np.uint8), float(spec.cell_size),
                         np.uint8(_MOVING))
    n = len(agents)
    if n:
        c, s = math.cos(yaw), math.sin(yaw)
        rel = np.asarray(agents.xy, dtype=np.float64) - (px, py)
        ex = c * rel[:, 0] + s * rel[:, 1]
        ey = -s * rel[:, 0] + c * rel[:, 1]
        moving = np.asarray(agents.speed) > moving_threshold
        cls = np.where(moving, _MOVING, _STATIC).astype(np.uint8)
        _paint_boxes(out, ex, ey, np.asarray(agents.yaw, dtype=np.float64) - yaw,
                     np.asarray(agents.length, dtype=np.float64) / 2,
                     np.asarray(agents.width, dtype=np.float64) / 2,
                     cls, float(spec.cell_size), np.uint8(_MOVING))
    return out


def visible_mask(sensor: np.ndarray) -> np.ndarray:
    """Cells the sensor observed this sweep.

    Args:
        sensor: ``(H, W) uint8`` sensor grid (:class:`dstenv.dst.SensorState`).

    Returns:
        ``(H, W) bool``: true where the cell is free or occupied (not unknown).
    """
    return np.asarray(sensor) != SensorState.UNKNOWN


@numba.njit(cache=True)
def _paint_boxes(out, ex, ey, eyaw, hl, hw, cls, c, moving):  # pragma: no cover - numba
    h, w = out.shape
    i0 = h // 2
    j0 = w // 2
    for k in range(ex.shape[0]):
        ca = math.cos(eyaw[k])
        sa = math.sin(eyaw[k])
        # half extents of the box's axis-aligned hull in the ego frame
        rx = abs(ca) * hl[k] + abs(sa) * hw[k]
        ry = abs(sa) * hl[k] + abs(ca) * hw[k]
        # x = (i0 - i) c  =>  i = i0 - x / c ; hull rows / columns, clipped to the grid
        # (one cell of margin: the exact test below decides boundary cells)
        i_lo = max(int(math.floor(i0 - (ex[k] + rx) / c)), 0)
        i_hi = min(int(math.ceil(i0 - (ex[k] - rx) / c)), h - 1)
        j_lo = max(int(math.floor(j0 - (ey[k] + ry) / c)), 0)
        j_hi = min(int(math.ceil(j0 - (ey[k] - ry) / c)), w - 1)
        painted = False
        for i in range(i_lo, i_hi + 1):
            dx = (i0 - i) * c - ex[k]
            for j in range(j_lo, j_hi + 1):
                dy = (j0 - j) * c - ey[k]
                lx = ca * dx + sa * dy
                ly = -sa * dx + ca * dy
                if abs(lx) <= hl[k] and abs(ly) <= hw[k]:
                    painted = True
                    if out[i, j] != moving:
                        out[i, j] = cls[k]
        if not painted:
            # smaller than a cell: label the cell holding its centre (GridSpec.to_cell)
            i = int(math.floor(i0 - ex[k] / c + 0.5))
            j = int(math.floor(j0 - ey[k] / c + 0.5))
            if 0 <= i < h and 0 <= j < w and out[i, j] != moving:
                out[i, j] = cls[k]
