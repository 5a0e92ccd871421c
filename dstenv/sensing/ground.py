"""Ground removal of a 3-D point cloud: a seeded RANSAC plane and a local ground walk.

The first half of the point-cloud road (:mod:`dstenv.sensing.cloud`), shared by KITTI
scans and the simulated ``hdl64`` LIDAR. Road returns must count as free space, not
obstacles (as in the paper). The fit:

1. candidates: points within ``fit_range`` metres horizontally and below
   ``max_candidate_z`` (the Velodyne is 1.73 m above the road, so the road is
   near z = -1.7); at most ``sample`` of them, drawn with the seeded generator;
2. ``iterations`` random triplets -> planes, each scored by its inlier count;
   planes tilted more than ``max_tilt_deg`` from horizontal are rejected;
3. the best plane is refit by least squares to its inliers, twice.

A global plane misreads sloping verges and dips, so :func:`ground_heights` then
walks outwards through polar bins (1 deg x 1 m) of every azimuth sector, taking
the lowest return of a *flat* bin (returns spanning at most ``flat_spread``; a
bin holding a car's side spans its height) as the local ground when it rises
less than ``step_tolerance + max_slope * distance`` (and drops less than the
drop limits) since the last ground bin; other bins keep the last ground height.
Every point then gets a height above that local ground; :func:`classify_points`
splits the scan into ground (free-space rays), obstacles (a height band) and
the rest (ignored: overhanging branches, the car's own body, curbs).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from dstenv.config import Validated, merge_config
from dstenv.sensing.ransac import best_plane, candidates, refit, sample_candidates

__all__ = ["CloudError", "default_ground_config", "fit_ground_plane", "ground_heights",
           "classify_points", "ground_config", "ground_walk", "polar_coordinates",
           "prepare_points"]


class CloudError(ValueError):
    """A scan the ground fit cannot use (too few points near the road, no level plane)."""


def default_ground_config() -> dict[str, Any]:
    """Parameters of ground removal and obstacle selection (units in comments)."""
    return {
        "iterations": 200,  # RANSAC hypotheses
        "sample": 4000,  # candidate points scored per hypothesis
        "fit_range": 30.0,  # [m] horizontal range of candidate points
        "max_candidate_z": -0.8,  # [m] candidates lie below this height (sensor frame)
        "inlier_distance": 0.15,  # [m] RANSAC / refit inlier band
        "max_tilt_deg": 15.0,  # [deg] steepest accepted ground plane
        "ground_height": 0.25,  # [m] points below this height above the plane are ground
        "min_obstacle_height": 0.30,  # [m] obstacle band: lower bound above ground
        "max_obstacle_height": 2.50,  # [m] obstacle band: upper bound above ground
        "ego_radius": 2.7,  # [m] points closer than this (horizontally) are the ego car
        # local ground: per azimuth sector, walk outwards through range bins keeping
        # the lowest return of a flat bin as the ground when it rises no more than
        # step_tolerance + max_slope * distance since the last ground bin
        "local": True,  # refine the plane by the polar walk (False: plane only)
        "sector_deg": 1.0,  # [deg] azimuth sector width
        "bin_size": 1.0,  # [m] range bin length
        "max_slope": 0.12,  # [m/m] steepest ground rise between ground bins
        "step_tolerance": 0.15,  # [m] rise always accepted between neighbouring bins
        "flat_spread": 0.3,  # [m] a ground bin's returns span at most this height
        "max_drop_slope": 0.3,  # [m/m] steepest ground drop (ditches) between ground bins
        "drop_tolerance": 0.3,  # [m] drop always accepted between neighbouring bins
        "seed": 0,  # RANSAC generator seed (same seed, same result)
    }



def ground_config(config: dict[str, Any] | None) -> Validated:
    """Ground settings merged over :func:`default_ground_config` and marked validated
    (a validated one is passed through: the stages of one scan merge once)."""
    if isinstance(config, Validated):
        return config
    return Validated(merge_config(default_ground_config(), config, "ground"))


def _as_float(points: np.ndarray) -> np.ndarray:
    """``points`` as they are if float32 or float64 (the kernels widen float32 values
    to float64 where they compute: the same results as a float64 copy), else float64."""
    pts = np.asarray(points)
    return pts if pts.dtype in (np.float32, np.float64) else pts.astype(np.float64)


def fit_ground_plane(points: np.ndarray, config: dict[str, Any] | None = None, *,
                     polar: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Fit the ground plane of one scan.

    Args:
        points: ``(P, 3+) float`` Velodyne points (x, y, z, ...).
        config: overrides of :func:`default_ground_config`.
        polar: the points' ``(r, angle)`` if already computed (a speed-up).

    Returns:
        ``(4,) float64`` plane ``(a, b, c, d)`` with unit normal ``(a, b, c)``,
        ``c > 0``; the height of a point above the ground is ``a x + b y + c z + d``.

    Raises:
        CloudError: if fewer than 3 candidate points or no acceptable plane exist.
    """
    cfg = ground_config(config)
    xyz = _as_float(points)[:, :3]
    r = (polar or polar_coordinates(xyz))[0]
    pick = candidates(xyz, r, float(cfg["fit_range"]), float(cfg["ego_radius"]),
                       float(cfg["max_candidate_z"]))
    if len(pick) < 3:
        raise CloudError(f"ground fit: only {len(pick)} candidate points near the road")
    pick, tri = sample_candidates(pick, int(cfg["sample"]), int(cfg["iterations"]), cfg["seed"])
    cand, best, plane = best_plane(xyz, pick, tri, math.cos(math.radians(cfg["max_tilt_deg"])),
                                float(cfg["inlier_distance"]))
    if best < 0:
        raise CloudError("ground fit: no near-horizontal plane among the RANSAC hypotheses")
    # least-squares refit on the inliers, twice
    return refit(cand, plane, float(cfg["inlier_distance"]), 2)


def ground_heights(
    points: np.ndarray, plane: np.ndarray, config: dict[str, Any] | None = None, *,
    polar: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Height of every point above the local ground.

    The plane removes the sensor's tilt; with ``local`` on, a polar walk then
    follows gentle slopes and verges the plane misses (a field rising beside the
    road would otherwise read as an obstacle ring).

    Args:
        points: ``(P, 3+) float`` Velodyne points.
        plane: ``(4,)`` from :func:`fit_ground_plane`.
        config: overrides of :func:`default_ground_config`.
        polar: the points' ``(r, angle)`` if already computed (a speed-up).

    Returns:
        ``(P,) float64`` height above ground [m].
    """
    cfg = ground_config(config)
    xyz = _as_float(points)[:, :3]
    if not cfg["local"] or len(xyz) == 0:
        return xyz @ plane[:3] + plane[3]
    return _local_ground(*_walk_args(xyz, plane, cfg, polar))


def ground_walk(
    points: np.ndarray, plane: np.ndarray, config: dict[str, Any] | None = None, *,
    polar: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The local ground of :func:`ground_heights` as a table, for callers that fuse the
    last subtraction into their own pass (:func:`dstenv.sensing.cloud.cloud_sensor_grid`).

    Returns:
        ``(h, cell, flat)``: ``(P,) float64`` heights above the plane, ``(P,) int64``
        polar bin of each point and ``(B,) float64`` local ground per bin above the
        plane; ``h - flat[cell]`` is :func:`ground_heights` (``local`` off: ``cell`` all
        0 and ``flat = [0.0]``).
    """
    cfg = ground_config(config)
    xyz = _as_float(points)[:, :3]
    if not cfg["local"] or len(xyz) == 0:
        return xyz @ plane[:3] + plane[3], np.zeros(len(xyz), np.int64), np.zeros(1)
    return _ground_walk(*_walk_args(xyz, plane, cfg, polar))


def _walk_args(xyz: np.ndarray, plane: np.ndarray, cfg: dict[str, Any],
               polar: tuple[np.ndarray, np.ndarray] | None) -> tuple:
    """The arguments of the local-ground kernels (:func:`_local_ground`, :func:`_ground_walk`)."""
    n_sec = max(round(360.0 / cfg["sector_deg"]), 1)
    r, angle = polar or polar_coordinates(xyz)
    return (xyz, np.asarray(plane, dtype=np.float64), r, angle, n_sec,
            float(cfg["bin_size"]), float(cfg["ego_radius"]), float(cfg["max_slope"]),
            float(cfg["step_tolerance"]), float(cfg["flat_spread"]), float(cfg["max_drop_slope"]),
            float(cfg["drop_tolerance"]))


def classify_points(
    points: np.ndarray, plane: np.ndarray, config: dict[str, Any] | None = None, *,
    polar: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split a scan into ground and obstacle points.

    Args:
        points: ``(P, 3+) float`` Velodyne points.
        plane: ``(4,)`` from :func:`fit_ground_plane`.
        config: overrides of :func:`default_ground_config`.
        polar: the points' ``(r, angle)`` if already computed (a speed-up).

    Returns:
        ``(ground, obstacle, height)``: two disjoint ``(P,) bool`` masks and the
        ``(P,) float64`` heights above the local ground [m]. Points in neither
        mask (more than 3 m below the plane, between the bands, above the
        obstacle band, or on the ego car) are not used.
    """
    cfg = ground_config(config)
    xyz = _as_float(points)[:, :3]
    polar = polar or polar_coordinates(xyz)
    height = ground_heights(xyz, plane, cfg, polar=polar)
    ground, obstacle = _split(polar[0], height, float(cfg["ego_radius"]),
                              float(cfg["ground_height"]), float(cfg["min_obstacle_height"]),
                              float(cfg["max_obstacle_height"]))
    return ground, obstacle, height


@numba.njit(cache=True)
def _split(r, height, ego_radius, ground_height, low, high):  # pragma: no cover - numba
    """Ground and obstacle masks: away from the ego, height in the ground band (down
    to 3 m below: ditches and lower verges are free space too) or in [low, high]."""
    n = r.shape[0]
    ground = np.empty(n, np.bool_)
    obstacle = np.empty(n, np.bool_)
    for p in range(n):
        away = r[p] > ego_radius
        h = height[p]
        ground[p] = away and -3.0 < h < ground_height
        obstacle[p] = away and low <= h <= high
    return ground, obstacle


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


@numba.njit(cache=True)
def _local_ground(xyz, plane, r_all, angle, n_sec, bin_size, ego_radius, max_slope, step_tol,
                  flat_spread, max_drop_slope, drop_tol):  # pragma: no cover - numba
    """Heights above the local ground of the polar walk (see :func:`ground_heights`)."""
    h, cell, flat = _ground_walk(xyz, plane, r_all, angle, n_sec, bin_size, ego_radius,
                                 max_slope, step_tol, flat_spread, max_drop_slope, drop_tol)
    out = np.empty(h.shape[0])
    for p in range(h.shape[0]):
        out[p] = h[p] - flat[cell[p]]
    return out


@numba.njit(cache=True)
def _ground_walk(xyz, plane, r_all, angle, n_sec, bin_size, ego_radius, max_slope, step_tol,
                 flat_spread, max_drop_slope, drop_tol):  # pragma: no cover - numba
    """The polar walk: ``(h, cell, flat)``, heights ``(P,)`` above the plane, polar bin
    ``(P,) int64`` of every point and local ground ``(n_sec * n_bin,)`` above the plane;
    a point's height above the local ground is ``h[p] - flat[cell[p]]``."""
    n = r_all.shape[0]
    h = np.empty(n)  # above the plane
    a, b, c, d = plane[0], plane[1], plane[2], plane[3]
    for p in range(n):  # its own loop: it vectorises
        h[p] = a * xyz[p, 0] + b * xyz[p, 1] + c * xyz[p, 2] + d
    n_bin = int(math.ceil(np.max(r_all) / bin_size)) + 1
    # products by reciprocals, not divisions: this loop's cost (bins may differ from
    # the quotients' only for a value within an ulp of a bin edge)
    to_sec = n_sec / (2 * math.pi)
    inv_bin = 1.0 / bin_size
    cell = np.empty(n, np.int64)  # sector * n_bin + range bin of every point
    for p in range(n):  # the bins alone: a loop that vectorises
        s = min(int((angle[p] + math.pi) * to_sec), n_sec - 1)
        cell[p] = s * n_bin + int(r_all[p] * inv_bin)
    lowest = np.full((n_sec, n_bin), np.inf)
    highest = np.full((n_sec, n_bin), -np.inf)
    low = lowest.reshape(n_sec * n_bin)  # flat views, indexed by cell
    high = highest.reshape(n_sec * n_bin)
    for p in range(n):  # then the scattered lowest / highest
        hp = h[p]
        q = cell[p]
        low[q] = min(low[q], hp)
        high[q] = max(high[q], hp)
    ground = np.zeros((n_sec, n_bin))
    first = int(ego_radius / bin_size)
    for s in range(n_sec):
        g = 0.0  # the plane is the ground next to the car
        last_r = ego_radius
        for k in range(first, n_bin):
            rc = (k + 0.5) * bin_size
            cand = lowest[s, k]
            # a bin holding a vertical surface (a car's side) spans its height: never ground
            if highest[s, k] - cand <= flat_spread and math.isfinite(cand):
                dr = rc - last_r
                # a lower outlier (a reflection) must not drag the ground down
                rise_ok = cand - g <= step_tol + max_slope * dr
                if rise_ok and g - cand <= drop_tol + max_drop_slope * dr:
                    g = cand
                    last_r = rc
            ground[s, k] = g
    return h, cell, ground.ravel()
