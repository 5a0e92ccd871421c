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
from dstenv.sim.types import Agents, MapClass, Obstacles, WorldMap

__all__ = ["label_grid", "visible_mask", "ignore_object_edges", "MAP_TO_CLASS",
           "GROUND_CLEARANCE"]

#: clutter whose bottom is lower than this stands on the ground and is labelled [m]
GROUND_CLEARANCE: float = 0.3

_NAV = CLASSES.index("navigable")
_NONNAV = CLASSES.index("non_navigable")
_BUILDING = CLASSES.index("building")
_STATIC = CLASSES.index("static")
_MOVING = CLASSES.index("moving")
_SKIP = 255  # _paint_boxes: a box that is not painted
# a numpy scalar: comparing an array with the IntEnum member itself is ~10x slower
_UNKNOWN = np.uint8(SensorState.UNKNOWN)
_OCCUPIED = np.uint8(SensorState.OCCUPIED)

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
    c, s = math.cos(yaw), math.sin(yaw)
    obs = world_map.obstacles
    if len(obs):
        reach = 0.75 * spec.cell_size * max(spec.shape) + 10.0  # > half diagonal + box size
        _paint_boxes(out, *_clutter(obs),
                     px, py, yaw, c, s, reach, float(spec.cell_size), np.uint8(_MOVING))
    if len(agents):
        cls = np.where(np.asarray(agents.speed) > moving_threshold, _MOVING, _STATIC)
        _paint_boxes(out, *_f64(agents.xy, agents.yaw, agents.length, agents.width),
                     cls.astype(np.uint8), px, py, yaw, c, s, np.inf, float(spec.cell_size),
                     np.uint8(_MOVING))
    return out


def visible_mask(sensor: np.ndarray) -> np.ndarray:
    """Cells the sensor observed this sweep.

    Args:
        sensor: ``(H, W) uint8`` sensor grid (:class:`dstenv.dst.SensorState`).

    Returns:
        ``(H, W) bool``: true where the cell is free or occupied (not unknown).
    """
    return np.asarray(sensor) != _UNKNOWN


def ignore_object_edges(labels: np.ndarray, sensor: np.ndarray, ignore: int) -> int:
    """Label as ``ignore`` the occupied cells just outside a road user (in place).

    A LIDAR return on a body's surface often falls in a cell whose centre lies
    outside the body's box: :func:`label_grid` then gives that cell the class of the
    ground under it (usually ``navigable``), though it holds the body's hits. KITTI's
    converter without a map leaves such cells ignored (occupied, no box, no map
    class: :mod:`dstenv.kitti.grids`), so a network trained on simulated labels
    would learn to call the rim of every car blob ``navigable`` where KITTI never
    asks. This rule makes the simulated labels ask what KITTI's ask: an occupied
    cell that is not ``static`` / ``moving`` and has one of those among its 8
    neighbours becomes ``ignore`` (``protocol.object_edges = "ignore"``).

    Args:
        labels: ``(H, W) uint8`` class indices (:func:`label_grid`), changed in place.
        sensor: ``(H, W) uint8`` sensor grid of the same step (:class:`SensorState`).
        ignore: the ignore index (:data:`dstenv.frame.IGNORE_INDEX`).

    Returns:
        The number of cells set to ``ignore``.
    """
    if labels.shape != sensor.shape:
        raise ValueError(f"ignore_object_edges: labels {labels.shape} and sensor "
                         f"{sensor.shape} differ in shape")
    return int(_ignore_edges(labels, np.ascontiguousarray(sensor, dtype=np.uint8),
                             np.uint8(ignore)))


@numba.njit(cache=True)
def _ignore_edges(labels, sensor, ignore):  # pragma: no cover - numba
    """:func:`ignore_object_edges` (the object test reads the labels before any change:
    the ignored cells are never objects themselves)."""
    h, w = labels.shape
    n = 0
    for i in range(h):
        for j in range(w):
            lab = labels[i, j]
            if sensor[i, j] != _OCCUPIED or lab == _STATIC or lab == _MOVING:
                continue
            hit = False
            for di in range(-1, 2):
                ii = i + di
                if ii < 0 or ii >= h:
                    continue
                for dj in range(-1, 2):
                    jj = j + dj
                    if 0 <= jj < w:
                        q = labels[ii, jj]
                        if q == _STATIC or q == _MOVING:
                            hit = True
            if hit:
                labels[i, j] = ignore
                n += 1
    return n


# the last map's clutter as _paint_boxes takes it (a map's obstacles do not change)
_CLUTTER: list[tuple[Obstacles, tuple[np.ndarray, ...]]] = []


def _clutter(obs: Obstacles) -> tuple[np.ndarray, ...]:
    """``(xy, yaw, length, width, cls)`` of street clutter for :func:`_paint_boxes`:
    float64 arrays and the class painted (``_SKIP`` above the ground), kept for the
    last ``Obstacles`` seen (a label grid per frame of one map: ~10 us a frame)."""
    if _CLUTTER and _CLUTTER[0][0] is obs:
        return _CLUTTER[0][1]
    cls = np.where(obs.z_min < GROUND_CLEARANCE, _NONNAV, _SKIP).astype(np.uint8)
    arrays = (*_f64(obs.xy, obs.yaw, obs.length, obs.width), cls)
    _CLUTTER[:] = [(obs, arrays)]
    return arrays


def _f64(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    return tuple(np.ascontiguousarray(x, dtype=np.float64) for x in arrays)


@numba.njit(cache=True)
def _paint_boxes(out, xy, yaw, length, width, cls, px, py, pyaw, c, s, reach, cell,
                 moving):  # pragma: no cover - numba
    """Paint oriented boxes given in the world frame into the ego grid ``out``.

    Box ``k`` (centre ``xy[k]``, heading ``yaw[k]``, full ``length`` / ``width``)
    gets class ``cls[k]`` (:data:`_SKIP`: not painted) on the cells whose centre it
    holds, only in the rows and columns of its hull; ``moving`` is never
    overwritten. Boxes whose centre is ``reach`` [m] or more from the ego along a
    world axis are skipped (the caller's bound on what can touch the grid).
    ``c``, ``s``: cosine and sine of the ego heading ``pyaw``.
    """
    h, w = out.shape
    i0 = h // 2
    j0 = w // 2
    for k in range(xy.shape[0]):
        if cls[k] == _SKIP:
            continue
        rx = xy[k, 0] - px
        ry = xy[k, 1] - py
        if not (abs(rx) < reach and abs(ry) < reach):
            continue
        ex = c * rx + s * ry  # centre and heading in the ego frame
        ey = -s * rx + c * ry
        eyaw = yaw[k] - pyaw
        hl = length[k] / 2
        hw = width[k] / 2
        ca = math.cos(eyaw)
        sa = math.sin(eyaw)
        # half extents of the box's axis-aligned hull in the ego frame
        rhx = abs(ca) * hl + abs(sa) * hw
        rhy = abs(sa) * hl + abs(ca) * hw
        # x = (i0 - i) c  =>  i = i0 - x / c ; hull rows / columns, clipped to the grid
        # (one cell of margin: the exact test below decides boundary cells)
        i_lo = max(int(math.floor(i0 - (ex + rhx) / cell)), 0)
        i_hi = min(int(math.ceil(i0 - (ex - rhx) / cell)), h - 1)
        j_lo = max(int(math.floor(j0 - (ey + rhy) / cell)), 0)
        j_hi = min(int(math.ceil(j0 - (ey - rhy) / cell)), w - 1)
        painted = False
        for i in range(i_lo, i_hi + 1):
            dx = (i0 - i) * cell - ex
            for j in range(j_lo, j_hi + 1):
                dy = (j0 - j) * cell - ey
                lx = ca * dx + sa * dy
                ly = -sa * dx + ca * dy
                if abs(lx) <= hl and abs(ly) <= hw:
                    painted = True
                    if out[i, j] != moving:
                        out[i, j] = cls[k]
        if not painted:
            # smaller than a cell: label the cell holding its centre (GridSpec.to_cell)
            i = int(math.floor(i0 - ex / cell + 0.5))
            j = int(math.floor(j0 - ey / cell + 0.5))
            if 0 <= i < h and 0 <= j < w and out[i, j] != moving:
                out[i, j] = cls[k]
