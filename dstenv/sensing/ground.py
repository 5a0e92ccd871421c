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
from dstenv.sensing.polar import polar_coordinates
from dstenv.sensing.ransac import best_plane, candidates, refit, sample_candidates

__all__ = ["CloudError", "default_ground_config", "fit_ground_plane", "ground_heights",
           "classify_points", "ground_config", "ground_walk"]


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
