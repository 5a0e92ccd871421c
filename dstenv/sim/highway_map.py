"""The map of a highway-env scene (:mod:`dstenv.sim.highway`): its lanes rasterised as
road in dstenv's y-up frame (highway-env's y-down coordinates mirrored, ``y -> -y``),
and seeded rectangular buildings off the road that occlude the LIDAR as in a city.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dstenv.config import ConfigError
from dstenv.sim.types import MapClass

__all__ = ["mirror", "lane_points", "rasterise_lanes", "place_buildings"]


def mirror(xy: np.ndarray) -> np.ndarray:
    """highway-env (y-down) points -> the y-up world frame: ``(..., 2) float64``."""
    out = np.array(xy, dtype=np.float64)
    out[..., 1] *= -1.0
    return out


def lane_points(lane: Any, s: np.ndarray, r: np.ndarray) -> np.ndarray:
    """World points (highway frame) of lane coordinates: ``(len(s), len(r), 2)``."""
    from highway_env.road.lane import CircularLane, StraightLane

    ss, rr = np.meshgrid(s, r, indexing="ij")
    if type(lane) is StraightLane:
        return (lane.start + ss[..., None] * lane.direction
                + rr[..., None] * lane.direction_lateral)
    if type(lane) is CircularLane:
        phi = lane.direction * ss / lane.radius + lane.start_phase
        rad = lane.radius - rr * lane.direction
        return lane.center + np.stack([rad * np.cos(phi), rad * np.sin(phi)], -1)
    pts = [lane.position(a, b) for a, b in zip(ss.ravel(), rr.ravel())]
    return np.asarray(pts, dtype=np.float64).reshape(*ss.shape, 2)


def rasterise_lanes(lanes: list, bounds: tuple[float, float, float, float],
                    resolution: float) -> np.ndarray:
    """Road raster of highway-env lanes (mirrored into the y-up frame).

    Args:
        lanes: highway-env ``AbstractLane`` objects.
        bounds: ``(x_min, x_max, y_min, y_max)`` [m] of the raster (y-up frame).
        resolution: cell size [m].

    Returns:
        ``(Hm, Wm) uint8`` raster: ``MapClass.ROAD`` on lanes, ``INTERMEDIATE`` elsewhere.
    """
    x0, x1, y0, y1 = bounds
    w = int(np.ceil((x1 - x0) / resolution))
    h = int(np.ceil((y1 - y0) / resolution))
    raster = np.full((h, w), MapClass.INTERMEDIATE, np.uint8)
    step = resolution / 2
    for lane in lanes:
        # restrict long lanes to the part inside the raster before sampling densely
        s_coarse = np.linspace(0.0, lane.length, max(2, int(np.ceil(lane.length / 2.0)) + 1))
        c = mirror(lane_points(lane, s_coarse, np.zeros(1))[:, 0])
        pad = 2.0 + lane.width_at(0.0)
        inside = (c[:, 0] >= x0 - pad) & (c[:, 0] <= x1 + pad) & (c[:, 1] >= y0 - pad) & (
            c[:, 1] <= y1 + pad)
        if not inside.any():
            continue
        idx = np.flatnonzero(inside)
        s_lo = s_coarse[max(idx[0] - 1, 0)]
        s_hi = s_coarse[min(idx[-1] + 1, len(s_coarse) - 1)]
        half = lane.width_at(0.5 * (s_lo + s_hi)) / 2
        s = np.arange(s_lo, s_hi + step, step)
        r = np.arange(-half + step / 2, half, step)
        p = mirror(lane_points(lane, s, r)).reshape(-1, 2)
        col = np.floor((p[:, 0] - x0) / resolution).astype(np.int64)
        row = np.floor((p[:, 1] - y0) / resolution).astype(np.int64)
        ok = (row >= 0) & (row < h) & (col >= 0) & (col < w)
        raster[row[ok], col[ok]] = MapClass.ROAD
    return raster


def place_buildings(raster: np.ndarray, origin: tuple[float, float], resolution: float,
                    cfg: dict[str, Any], rng: np.random.Generator) -> list[np.ndarray]:
    """Place axis-aligned rectangular buildings off-road, in place on ``raster``.

    Three candidates in four face a street: their near edge lies ``setback`` plus
    0-6 m from a random road cell, in a random direction (buildings line the roads
    and hide the junctions, as in a city); the rest are uniform. A candidate is kept
    when no road cell lies within ``setback`` of it and no building within ``gap``.

    Args:
        raster: ``(Hm, Wm) uint8`` map raster, modified in place (``BUILDING`` cells).
        origin: world ``(x0, y0)`` of the raster corner [m].
        resolution: raster cell size [m].
        cfg: the ``buildings`` config section.
        rng: source of randomness.

    Returns:
        Footprints, each ``(4, 2) float64`` counter-clockwise world polygon.
    """
    h, w = raster.shape
    area_ha = h * w * resolution**2 / 1e4
    target = int(round(cfg["per_hectare"] * area_ha))
    smin, smax = cfg["size_min"], cfg["size_max"]
    if not 0 < smin <= smax:
        raise ConfigError(f"highway.buildings: need 0 < size_min <= size_max, got {smin}, {smax}")
    set_c = int(np.ceil(cfg["setback"] / resolution))
    gap_c = int(np.ceil(cfg["gap"] / resolution))
    road_r, road_c = np.nonzero(raster == MapClass.ROAD)
    polys: list[np.ndarray] = []
    for _ in range(30 * target):
        if len(polys) >= target:
            break
        bw, bh = rng.uniform(smin, smax, size=2) / resolution
        if len(road_r) and rng.random() < 0.75:
            k = int(rng.integers(len(road_r)))
            ang = rng.uniform(0.0, 2 * np.pi)
            # distance from the road cell to the centre: setback + slack + half extent
            reach = (set_c + rng.uniform(0.0, 6.0 / resolution)
                     + 0.5 * (abs(np.cos(ang)) * bw + abs(np.sin(ang)) * bh))
            cc = road_c[k] + reach * np.cos(ang)
            rc = road_r[k] + reach * np.sin(ang)
            c0, r0 = int(round(cc - bw / 2)), int(round(rc - bh / 2))
        else:
            c0 = int(rng.integers(0, max(1, w - int(bw))))
            r0 = int(rng.integers(0, max(1, h - int(bh))))
        c1, r1 = c0 + int(bw), r0 + int(bh)
        if c0 < 0 or r0 < 0 or c1 > w or r1 > h:
            continue
        near = raster[max(0, r0 - set_c):r1 + set_c, max(0, c0 - set_c):c1 + set_c]
        if (near == MapClass.ROAD).any():
            continue
        near = raster[max(0, r0 - gap_c):r1 + gap_c, max(0, c0 - gap_c):c1 + gap_c]
        if (near == MapClass.BUILDING).any():
            continue
        raster[r0:r1, c0:c1] = MapClass.BUILDING
        x0, y0 = origin[0] + c0 * resolution, origin[1] + r0 * resolution
        x1, y1 = origin[0] + c1 * resolution, origin[1] + r1 * resolution
        polys.append(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64))
    return polys
