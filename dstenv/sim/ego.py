"""The ego vehicle: kinematic bicycle model, pure-pursuit steering, collision tests."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dstenv.sim.raster import lookup
from dstenv.sim.types import MapClass, WorldMap

BUILDING, ROAD = int(MapClass.BUILDING), int(MapClass.ROAD)

__all__ = ["bicycle_step", "pure_pursuit", "pursuit_lookahead", "box_corners", "boxes_overlap",
           "box_overlap", "footprint_classes", "hits"]


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


def pursuit_lookahead(v: float) -> float:
    """Look-ahead [m] of the route-following steering rule at speed ``v`` [m/s].

    ``clip(2.5 + 0.4 v, 3.5, 12)``, measured from the rear axle: the one rule of the
    autopilot and of the env's meta-actions (:meth:`dstenv.sim.World.route_steer`).
    Short enough at 9-10 m/s (~6.5 m) that the rear axle tracks junction turns of
    ~8 m radius without cutting the corner off the road.
    """
    return float(min(max(2.5 + 0.4 * v, 3.5), 12.0))


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


@nb.njit(cache=True)
def box_overlap(x1, y1, h1, l1, w1, x2, y2, h2, l2, w2):
    """Separating-axis test of two oriented boxes (centre, yaw, half length, half width)."""
    dx, dy = x2 - x1, y2 - y1
    if dx * dx + dy * dy > (l1 + w1 + l2 + w2) ** 2:
        return False
    c1, s1, c2, s2 = np.cos(h1), np.sin(h1), np.cos(h2), np.sin(h2)
    for ax, ay in ((c1, s1), (-s1, c1), (c2, s2), (-s2, c2)):
        r1 = l1 * abs(c1 * ax + s1 * ay) + w1 * abs(-s1 * ax + c1 * ay)
        r2 = l2 * abs(c2 * ax + s2 * ay) + w2 * abs(-s2 * ax + c2 * ay)
        if abs(dx * ax + dy * ay) >= r1 + r2 - 1e-9:
            return False
    return True


def hits(world_map: WorldMap, xy: np.ndarray, yaw: np.ndarray, half_len: np.ndarray,
         half_wid: np.ndarray, box: tuple[float, float, float, float, float]) -> tuple[bool, bool]:
    """``(collision, off_road)`` of a footprint.

    Args:
        world_map: the map (its raster decides building / road).
        xy, yaw, half_len, half_wid: the other bodies, ``(N, 2)`` / ``(N,)`` float64.
        box: ``(x, y, yaw, length, width)`` of the footprint.

    Returns:
        collision: it overlaps a body or a building cell; off_road: some part of it
        (corners, edge midpoints, centre) is not on a road cell.
    """
    x0, y0 = world_map.origin
    return _hits(world_map.raster, float(x0), float(y0), float(world_map.resolution),
                 float(box[0]), float(box[1]), float(box[2]), box[3] / 2, box[4] / 2,
                 xy, yaw, half_len, half_wid)


@nb.njit(cache=True)
def _hits(raster, x0, y0, res, x, y, yaw, hl, hw, axy, ayaw, ahl, ahw):
    c, s = np.cos(yaw), np.sin(yaw)
    h, w = raster.shape
    collide, off = False, False
    for a in (-1.0, -0.5, 0.0, 0.5, 1.0):
        for b in (-1.0, 0.0, 1.0):
            px = x + c * a * hl - s * b * hw
            py = y + s * a * hl + c * b * hw
            col = int(np.floor((px - x0) / res))
            row = int(np.floor((py - y0) / res))
            if row < 0 or row >= h or col < 0 or col >= w:
                off = True
                continue
            code = raster[row, col]
            collide = collide or code == BUILDING
            off = off or code != ROAD
    for j in range(axy.shape[0]):
        if box_overlap(x, y, yaw, hl, hw, axy[j, 0], axy[j, 1], ayaw[j], ahl[j], ahw[j]):
            collide = True
            break
    return collide, off
