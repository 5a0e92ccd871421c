"""The ego vehicle: kinematic bicycle model, pure-pursuit steering, collision tests."""

from __future__ import annotations

import math

import numpy as np

from dstenv.sim.raster import lookup
from dstenv.sim.types import Agents, MapClass, WorldMap

__all__ = ["bicycle_step", "pure_pursuit", "box_corners", "boxes_overlap", "footprint_classes"]


def bicycle_step(x: float, y: float, yaw: float, v: float, accel: float, steer: float,
                 wheelbase: float, dt: float,
                 max_speed: float) -> tuple[float, float, float, float]:
    """One step of the kinematic bicycle model about the vehicle's centre.

    The slip angle is ``beta = atan(tan(steer) / 2)`` (centre midway between the
    axles); the centre moves at heading ``yaw + beta`` on a circle of curvature
    ``2 sin(beta) / wheelbase``. The step is integrated exactly for constant
    steering and acceleration (speed clipped to ``[0, max_speed]``).

    Args:
        x, y, yaw, v: pose [m, m, rad] and speed [m/s] of the centre.
        accel: [m/s^2]; steer: front wheel angle [rad]; wheelbase: [m]; dt: [s].

    Returns:
        ``(x, y, yaw, v)`` after ``dt``.
    """
    v_new = v + accel * dt
    if v_new < 0.0:  # stops within the step
        dist = v * v / (-2.0 * accel) if accel < 0 else 0.0
        v_new = 0.0
    elif v_new > max_speed:
        t_up = max((max_speed - v) / accel, 0.0) if accel > 0 else 0.0
        dist = 0.5 * (v + max_speed) * t_up + max_speed * (dt - t_up)
        v_new = max_speed
    else:
        dist = 0.5 * (v + v_new) * dt
    beta = math.atan(0.5 * math.tan(steer))
    dpsi = dist * 2.0 * math.sin(beta) / wheelbase
    course = yaw + beta
    if abs(dpsi) < 1e-12:
        x += dist * math.cos(course)
        y += dist * math.sin(course)
    else:
        r = dist / dpsi
        x += r * (math.sin(course + dpsi) - math.sin(course))
        y -= r * (math.cos(course + dpsi) - math.cos(course))
    yaw = (yaw + dpsi + math.pi) % (2 * math.pi) - math.pi
    return x, y, yaw, v_new


def pure_pursuit(x: float, y: float, yaw: float, target: tuple[float, float],
                 wheelbase: float, max_steer: float) -> float:
    """Steering angle [rad] that carries the vehicle onto ``target`` (world point)."""
    dx, dy = target[0] - x, target[1] - y
    ld = max(math.hypot(dx, dy), 1e-3)
    alpha = math.atan2(dy, dx) - yaw
    steer = math.atan2(2.0 * wheelbase * math.sin(alpha), ld)
    return float(min(max(steer, -max_steer), max_steer))


def box_corners(x: float, y: float, yaw: float, length: float, width: float) -> np.ndarray:
    """Corners of an oriented box, counter-clockwise: ``(4, 2) float64``."""
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[length, width], [-length, width], [-length, -width], [length, -width]]) / 2
    return local @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def boxes_overlap(box: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Separating-axis test of one box against many.

    Args:
        box: ``(4, 2)`` corners; others: ``(N, 4, 2)`` corners (both as from
            :func:`box_corners` / :meth:`Agents.corners`).

    Returns:
        ``(N,) bool``: the interiors intersect.
    """
    if len(others) == 0:
        return np.zeros(0, bool)
    e0 = np.array([box[1] - box[0], box[2] - box[1]])  # (2, 2)
    e1 = np.stack([others[:, 1] - others[:, 0], others[:, 2] - others[:, 1]], 1)  # (N, 2, 2)
    axes = np.concatenate([np.broadcast_to(e0, (len(others), 2, 2)), e1], 1)  # (N, 4, 2)
    pa = np.einsum("nad,kd->nak", axes, box)  # (N, 4, 4)
    pb = np.einsum("nad,nkd->nak", axes, others)
    sep = (pa.max(-1) <= pb.min(-1) + 1e-9) | (pb.max(-1) <= pa.min(-1) + 1e-9)
    return ~sep.any(-1)


def footprint_classes(world_map: WorldMap, corners: np.ndarray, n_edge: int = 3) -> np.ndarray:
    """Map classes under points spread over a box footprint (corners, edges, centre).

    Args:
        corners: ``(4, 2)`` box corners.
        n_edge: points per edge besides the corners.

    Returns:
        ``(M,) uint8`` :class:`MapClass` codes.
    """
    t = np.linspace(0, 1, n_edge + 2)[:-1, None]
    edges = [corners[k] + t * (corners[(k + 1) % 4] - corners[k]) for k in range(4)]
    pts = np.vstack(edges + [corners.mean(0, keepdims=True)])
    return lookup(world_map, pts)


def hits(world_map: WorldMap, agents: Agents, corners: np.ndarray) -> tuple[bool, bool]:
    """``(collision, off_road)`` of a footprint: overlap with an agent or a building,
    or any part of it off the road."""
    cls = footprint_classes(world_map, corners)
    centre = corners.mean(0)
    near = np.flatnonzero(np.hypot(*(agents.xy - centre).T) < 8.0) if len(agents) else []
    collide = bool((cls == MapClass.BUILDING).any())
    if len(near):
        sub = Agents(agents.xy[near], agents.yaw[near], agents.speed[near], agents.length[near],
                     agents.width[near], agents.kind[near], agents.parked[near])
        collide = collide or bool(boxes_overlap(corners, sub.corners()).any())
    return collide, bool((cls != MapClass.ROAD).any())
