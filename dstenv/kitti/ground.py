"""Ground removal: a seeded, vectorised RANSAC plane fit refined by least squares.

Road returns must count as free space, not obstacles (as in the paper). The fit:

1. candidates: points within ``fit_range`` metres horizontally and below
   ``max_candidate_z`` (the Velodyne is 1.73 m above the road, so the road is
   near z = -1.7); at most ``sample`` of them, drawn with the seeded generator;
2. ``iterations`` random triplets -> planes, all scored at once as an
   ``(iterations, sample)`` distance matrix; planes tilted more than
   ``max_tilt_deg`` from horizontal are rejected;
3. the best plane is refit by least squares (SVD) to its inliers, twice.

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

from typing import Any

import numpy as np

from dstenv.config import merge_config
from dstenv.kitti.readers import KittiError

__all__ = ["default_ground_config", "fit_ground_plane", "ground_heights", "classify_points"]


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


def fit_ground_plane(points: np.ndarray, config: dict[str, Any] | None = None) -> np.ndarray:
    """Fit the ground plane of one scan.

    Args:
        points: ``(P, 3+) float`` Velodyne points (x, y, z, ...).
        config: overrides of :func:`default_ground_config`.

    Returns:
        ``(4,) float64`` plane ``(a, b, c, d)`` with unit normal ``(a, b, c)``,
        ``c > 0``; the height of a point above the ground is ``a x + b y + c z + d``.

    Raises:
        KittiError: if fewer than 3 candidate points or no acceptable plane exist.
    """
    cfg = merge_config(default_ground_config(), config, "ground")
    xyz = np.asarray(points, dtype=np.float64)[:, :3]
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    near = (r < cfg["fit_range"]) & (r > cfg["ego_radius"])
    cand = xyz[near & (xyz[:, 2] < cfg["max_candidate_z"])]
    if len(cand) < 3:
        raise KittiError(f"ground fit: only {len(cand)} candidate points near the road")
    rng = np.random.default_rng(cfg["seed"])
    if len(cand) > cfg["sample"]:
        cand = cand[rng.choice(len(cand), cfg["sample"], replace=False)]
    tri = cand[rng.integers(0, len(cand), size=(cfg["iterations"], 3))]  # (I, 3, 3)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(normal, axis=1)
    ok = norm > 1e-9
    normal[ok] /= norm[ok, None]
    normal *= np.where(normal[:, 2:3] < 0, -1.0, 1.0)  # point up
    ok &= normal[:, 2] >= np.cos(np.deg2rad(cfg["max_tilt_deg"]))
    if not ok.any():
        raise KittiError("ground fit: no near-horizontal plane among the RANSAC hypotheses")
    d = -np.einsum("ij,ij->i", normal, tri[:, 0])
    dist = np.abs(normal @ cand.T + d[:, None])  # (I, S)
    score = np.where(ok, (dist < cfg["inlier_distance"]).sum(axis=1), -1)
    plane = np.append(normal[np.argmax(score)], d[np.argmax(score)])
    for _ in range(2):  # least-squares refit on the inliers
        inl = cand[np.abs(cand @ plane[:3] + plane[3]) < cfg["inlier_distance"]]
        if len(inl) < 3:
            break
        centre = inl.mean(axis=0)
        n = np.linalg.svd(inl - centre, full_matrices=False)[2][-1]
        n = n if n[2] > 0 else -n
        plane = np.append(n, -n @ centre)
    return plane


def ground_heights(
    points: np.ndarray, plane: np.ndarray, config: dict[str, Any] | None = None
) -> np.ndarray:
    """Height of every point above the local ground.

    The plane removes the sensor's tilt; with ``local`` on, a polar walk then
    follows gentle slopes and verges the plane misses (a field rising beside the
    road would otherwise read as an obstacle ring).

    Args:
        points: ``(P, 3+) float`` Velodyne points.
        plane: ``(4,)`` from :func:`fit_ground_plane`.
        config: overrides of :func:`default_ground_config`.

    Returns:
        ``(P,) float64`` height above ground [m].
    """
    cfg = merge_config(default_ground_config(), config, "ground")
    xyz = np.asarray(points, dtype=np.float64)[:, :3]
    h = xyz @ plane[:3] + plane[3]
    if not cfg["local"] or len(h) == 0:
        return h
    n_sec = max(int(round(360.0 / cfg["sector_deg"])), 1)
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    sec = ((np.arctan2(xyz[:, 1], xyz[:, 0]) + np.pi) / (2 * np.pi) * n_sec).astype(np.int64)
    sec = np.minimum(sec, n_sec - 1)
    n_bin = int(np.ceil(r.max() / cfg["bin_size"])) + 1
    rbin = (r / cfg["bin_size"]).astype(np.int64)
    lowest = np.full((n_sec, n_bin), np.inf)
    np.minimum.at(lowest, (sec, rbin), h)
    highest = np.full((n_sec, n_bin), -np.inf)
    np.maximum.at(highest, (sec, rbin), h)
    # a bin holding a vertical surface (a car's side) spans its height: never ground
    lowest[highest - lowest > cfg["flat_spread"]] = np.inf
    ground = np.zeros((n_sec, n_bin))
    g = np.zeros(n_sec)  # the plane is the ground next to the car
    last_r = np.full(n_sec, cfg["ego_radius"])
    first = int(cfg["ego_radius"] / cfg["bin_size"])
    for b in range(first, n_bin):
        rc = (b + 0.5) * cfg["bin_size"]
        cand = lowest[:, b]
        dr = rc - last_r
        ok = (
            np.isfinite(cand)
            & (cand - g <= cfg["step_tolerance"] + cfg["max_slope"] * dr)
            & (g - cand <= cfg["drop_tolerance"] + cfg["max_drop_slope"] * dr)
        )  # a lower outlier (a reflection) must not drag the ground down
        g = np.where(ok, cand, g)
        last_r = np.where(ok, rc, last_r)
        ground[:, b] = g
    return h - ground[sec, rbin]


def classify_points(
    points: np.ndarray, plane: np.ndarray, config: dict[str, Any] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split a scan into ground and obstacle points.

    Args:
        points: ``(P, 3+) float`` Velodyne points.
        plane: ``(4,)`` from :func:`fit_ground_plane`.
        config: overrides of :func:`default_ground_config`.

    Returns:
        ``(ground, obstacle, height)``: two disjoint ``(P,) bool`` masks and the
        ``(P,) float64`` heights above the local ground [m]. Points in neither
        mask (more than 3 m below the plane, between the bands, above the
        obstacle band, or on the ego car) are not used.
    """
    cfg = merge_config(default_ground_config(), config, "ground")
    xyz = np.asarray(points, dtype=np.float64)[:, :3]
    height = ground_heights(xyz, plane, cfg)
    away = np.hypot(xyz[:, 0], xyz[:, 1]) > cfg["ego_radius"]
    # Returns below the road plane (ditches, lower verges) are free space too.
    ground = away & (height > -3.0) & (height < cfg["ground_height"])
    obstacle = (
        away & (height >= cfg["min_obstacle_height"]) & (height <= cfg["max_obstacle_height"])
    )
    return ground, obstacle, height
