"""Polar coordinates of a point cloud: horizontal range and azimuth in one vectorised
pass (float64 within 5e-16 rad of ``math.atan2``; float32 for the scan copy the stages
of the point-cloud road read, :func:`prepare_points`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["polar_coordinates", "prepare_points"]


def polar_coordinates(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(r, angle)`` of ``(P, 2+)`` points: ``(P,) float64`` horizontal range [m] and
    azimuth [rad] in [-pi, pi] (computed once, shared by the stages of the road).

    The azimuth is within 5e-16 rad of ``math.atan2`` (a vectorised Cephes atan,
    about five times faster than the C library's)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    return _polar_kernel(np.ascontiguousarray(xyz[:, 0]), np.ascontiguousarray(xyz[:, 1]))


def prepare_points(points: np.ndarray, offset: tuple[float, float] = (0.0, 0.0)
                   ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """The copy of a scan the stages of the road read, and its polar coordinates.

    float32, as the scan itself (the KITTI ``.bin`` layout, the simulated cloud): the
    copy of a float32 scan is exact (the stages widen its values to float64 where they
    compute, so planes and heights are those of a float64 copy; a float64 scan, or an
    ``offset``, is rounded to float32), the polar pass runs 8 lanes wide instead of 4
    and every pass after it reads half the bytes.

    Args:
        points: ``(P, 3+) float32 or float64`` Velodyne points (KITTI ``.bin`` rows).
        offset: ``(dx, dy)`` [m] added to x and y (a sensor's mount in the ego frame);
            ``(0, 0)`` leaves the points as they are.

    Returns:
        ``(xyz, (r, angle))``: ``(P, 3) float32`` column-major (each coordinate
        contiguous) and its polar coordinates, ``(P,) float32`` each
        (:func:`polar_coordinates` in float32: range within two ulps, azimuth within
        3e-7 rad); one pass over ``points``.
    """
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise ValueError(f"prepare_points: points must be (P, 3+), got shape {pts.shape}")
    if pts.dtype != np.float32 and pts.dtype != np.float64:
        pts = pts.astype(np.float64)
    dx, dy = float(offset[0]), float(offset[1])
    rows, r, a = _prepare_kernel(pts, dx, dy, dx != 0.0 or dy != 0.0)
    return rows.T, (r, a)


@numba.njit(cache=True)
def _prepare_kernel(pts, dx, dy, shift):  # pragma: no cover - numba
    """``(3, P) float32`` rows x + dx, y + dy, z and their polar coordinates."""
    n = pts.shape[0]
    rows = np.empty((3, n), np.float32)
    for p in range(n):
        rows[0, p] = pts[p, 0]
        rows[1, p] = pts[p, 1]
        rows[2, p] = pts[p, 2]
    if shift:
        for p in range(n):
            rows[0, p] = np.float32(rows[0, p] + dx)
            rows[1, p] = np.float32(rows[1, p] + dy)
    r, a = _polar32(rows[0], rows[1])
    return rows, r, a


# Cephes' atanf on [0, tan(pi/8)] (float32, relative error ~1e-7)
_F0, _F1, _F2, _F3 = (np.float32(8.05374449538e-2), np.float32(-1.38776856032e-1),
                      np.float32(1.99777106478e-1), np.float32(-3.33329491539e-1))
_TAN_PI8 = np.float32(0.4142135623730950)
_PI4_F, _PI2_F, _PI_F = np.float32(math.pi / 4), np.float32(math.pi / 2), np.float32(math.pi)
_ONE_F, _ZERO_F = np.float32(1.0), np.float32(0.0)


@numba.njit(cache=True, error_model="numpy")
def _polar32(x, y):  # pragma: no cover - numba
    """``(r, angle)`` of float32 ``x, y`` in float32 arithmetic, 8 lanes a vector: the
    range and Cephes' atanf of ``min(|x|, |y|) / max(|x|, |y|)``, then the octant (as
    :func:`_polar_kernel`); points on an axis take ``math.atan2`` in a second pass."""
    n = x.shape[0]
    r = np.empty(n, np.float32)
    a = np.empty(n, np.float32)
    for p in range(n):
        xp = x[p]
        yp = y[p]
        r[p] = np.sqrt(xp * xp + yp * yp)
        ax = abs(xp)
        ay = abs(yp)
        t = min(ax, ay) / max(ax, ay)  # in [0, 1]; NaN at the origin (fixed below)
        big = t > _TAN_PI8
        t = (t - _ONE_F) / (t + _ONE_F) if big else t
        z = t * t
        v = (((_F0 * z + _F1) * z + _F2) * z + _F3) * z * t + t
        v = v + (_PI4_F if big else _ZERO_F)
        v = (_PI2_F - v) if ay > ax else v
        v = (_PI_F - v) if xp < _ZERO_F else v
        a[p] = -v if yp < _ZERO_F else v
    for p in range(n):
        if x[p] == 0.0 or y[p] == 0.0:
            a[p] = np.float32(math.atan2(y[p], x[p]))
    return r, a


# Cephes' atan on [0, 0.66] (rational approximation, relative error ~2e-16)
_P0, _P1, _P2, _P3, _P4 = (-8.750608600031904122785e-1, -1.615753718733365076637e1,
                           -7.500855792314704667340e1, -1.228866684490136173410e2,
                           -6.485021904942025371773e1)
_Q0, _Q1, _Q2, _Q3, _Q4 = (2.485846490142306297962e1, 1.650270098316988542046e2,
                           4.328810604912902668951e2, 4.853903996359136964868e2,
                           1.945506571482613964425e2)
_MOREBITS = 6.123233995736765886130e-17  # pi/4 - float(pi/4)


@numba.njit(cache=True, error_model="numpy")
def _polar_kernel(x, y):  # pragma: no cover - numba
    """Range and atan2 in one branch-free loop that vectorises: atan of
    ``min(|x|, |y|) / max(|x|, |y|)`` by Cephes' reduction, then the octant; points
    on an axis (a zero, signed) take ``math.atan2`` in a second pass."""
    n = x.shape[0]
    r = np.empty(n)
    a = np.empty(n)
    for p in range(n):
        xp = x[p]
        yp = y[p]
        r[p] = math.sqrt(xp * xp + yp * yp)
        ax = abs(xp)
        ay = abs(yp)
        t = min(ax, ay) / max(ax, ay)  # in [0, 1]; NaN at the origin (fixed below)
        big = t > 0.66
        t = (t - 1.0) / (t + 1.0) if big else t
        z = t * t
        num = (((_P0 * z + _P1) * z + _P2) * z + _P3) * z + _P4
        den = ((((z + _Q0) * z + _Q1) * z + _Q2) * z + _Q3) * z + _Q4
        v = ((math.pi / 4 if big else 0.0)
             + ((t * (z * num / den) + t) + (0.5 * _MOREBITS if big else 0.0)))
        v = (math.pi / 2 - v) if ay > ax else v
        v = (math.pi - v) if xp < 0.0 else v
        a[p] = -v if yp < 0.0 else v
    for p in range(n):
        if x[p] == 0.0 or y[p] == 0.0:
            a[p] = math.atan2(y[p], x[p])
    return r, a
