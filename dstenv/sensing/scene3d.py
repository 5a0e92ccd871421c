"""The scene as the 3-D LIDAR's caster reads it (:mod:`dstenv.sensing.lidar3d`): surface
codes and reflectances, and the tables of occluders it casts against.

* :func:`box_table`: one row per box (agents, the map's clutter, with ``car_shape`` the
  cars' other parts), rebuilt every sweep;
* :func:`clutter_table` and :func:`building_table`: the map's static geometry, built
  once per map.

Split from :mod:`dstenv.sensing.lidar3d` to keep both modules small.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dstenv.sensing.carshape import car_part_rows
from dstenv.sim.types import AgentKind, Agents, WorldMap

__all__ = ["SURFACES", "REFLECTANCE", "ROAD", "KERB", "BUILDING", "AGENT", "CLUTTER",
           "box_table", "clutter_table", "building_table"]

#: Surface codes of :attr:`dstenv.sensing.lidar3d.Cloud.surface`.
SURFACES: tuple[str, ...] = ("road", "kerb", "building", "agent", "clutter")
#: Mean reflectance per surface code (KITTI's median return is ~0.28).
REFLECTANCE: np.ndarray = np.array([0.22, 0.30, 0.35, 0.40, 0.25])
ROAD, KERB, BUILDING, AGENT, CLUTTER = range(5)


def box_table(agents: Agents, clutter: np.ndarray, car_shape: bool = False) -> np.ndarray:
    """``(K, 11)`` rows ``cx, cy, cos, sin, half_l, half_w, z_lo, z_hi, surface, index, r``:
    the agents, then the map's ``clutter`` rows (:func:`clutter_table`), then, with
    ``car_shape`` (``vehicle_shape = "car"``), the cars' other parts
    (:func:`dstenv.sensing.carshape.car_part_rows`; row ``i`` stays agent ``i``'s)."""
    if not len(agents):
        return clutter
    f64 = np.float64
    xy, yaw = np.ascontiguousarray(agents.xy, f64), np.asarray(agents.yaw, f64)
    length, width = np.asarray(agents.length, f64), np.asarray(agents.width, f64)
    height = np.asarray(agents.height, f64)
    rows = _agent_rows(xy, yaw, length, width, height, clutter)
    if not car_shape:
        return rows
    is_car = np.asarray(agents.kind) == AgentKind.CAR
    extra = car_part_rows(xy, yaw, length, width, height, is_car, float(AGENT), rows)
    return np.concatenate([rows, extra]) if len(extra) else rows


@numba.njit(cache=True)
def _agent_rows(xy, yaw, length, width, height, clutter):  # pragma: no cover - numba
    """The agents' box rows above ``clutter``'s, in one call (the values of NumPy's
    ``cos``, ``sin`` and ``hypot``, which are the C library's, as numba's)."""
    n = xy.shape[0]
    out = np.empty((n + clutter.shape[0], 11))
    for i in range(n):
        out[i, 0] = xy[i, 0]
        out[i, 1] = xy[i, 1]
        out[i, 2] = math.cos(yaw[i])
        out[i, 3] = math.sin(yaw[i])
        out[i, 4] = length[i] / 2
        out[i, 5] = width[i] / 2
        out[i, 6] = 0.0
        out[i, 7] = height[i]
        out[i, 8] = AGENT
        out[i, 9] = i
        out[i, 10] = math.hypot(length[i], width[i]) / 2
    out[n:] = clutter
    return out


def clutter_table(world_map: WorldMap) -> np.ndarray:
    """``(K, 11)`` box rows of the map's clutter (see :func:`box_table`)."""
    obs = world_map.obstacles
    if obs is None or not len(obs):
        return np.zeros((0, 11))
    n = len(obs)
    return np.ascontiguousarray(np.column_stack([
        obs.xy, np.cos(obs.yaw), np.sin(obs.yaw), obs.length / 2, obs.width / 2,
        obs.z_min, obs.z_max, np.full(n, CLUTTER), np.arange(n),
        np.hypot(obs.length, obs.width) / 2]), dtype=np.float64)


def building_table(world_map: WorldMap) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Edges ``(E, 4)`` (``x0, y0, x1, y1``; polygons closed, zero-length edges dropped),
    ``starts (B+1,)``, circles ``(B, 3)`` (vertex mean, farthest vertex) and heights;
    vectorised over all vertices (~7x faster than per building, the same arrays)."""
    polys = [np.asarray(p, dtype=np.float64) for p in world_map.buildings]
    heights = np.asarray(world_map.building_heights, np.float64)
    if not polys:
        return np.zeros((0, 4)), np.zeros(1, np.int64), np.zeros((0, 3)), heights
    n = np.array([len(p) for p in polys], np.int64)
    pts = np.concatenate(polys)
    first = np.concatenate([[0], np.cumsum(n)[:-1]])
    nxt = np.arange(len(pts)) + 1  # each vertex's successor, the last one's the first
    nxt[first + n - 1] = first
    e = np.concatenate([pts, pts[nxt]], axis=1)
    keep = np.any(e[:, :2] != e[:, 2:], axis=1)
    owner = np.repeat(np.arange(len(polys)), n)
    starts = np.zeros(len(polys) + 1, np.int64)
    np.cumsum(np.bincount(owner[keep], minlength=len(polys)), out=starts[1:])
    centre = np.stack([p.mean(axis=0) for p in polys])  # numpy's own sum order per polygon
    radius = np.maximum.reduceat(np.hypot(*(pts - centre[owner]).T), first)
    return np.ascontiguousarray(e[keep]), starts, np.column_stack([centre, radius]), heights
