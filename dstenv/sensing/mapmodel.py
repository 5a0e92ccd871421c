"""The map as a map provider (OpenStreetMap) would have it: drawn once per episode.

The label grid is cut from the true world raster; the GIS grid from this one. It
differs from the truth the way OSM differs from a street (all knobs in the ``gis``
section, see :func:`dstenv.sensing.config.default_gis_config`):

* buildings: some are missing (``missing_building_prob``), some extra ones stand
  where there is none (``extra_building_rate`` per true building, on open ground
  away from the roads), and every outline is shifted and scaled (``outline_shift_std``
  [m], ``outline_scale_std``), as traced from aerial images and simplified;
* roads (``road_width = "lanes"``): drawn around the street centre-lines with the
  width ``lanes x nominal_lane_width``, not the true surface (which has its own lane
  widths, kerb radii and parking strips);
* everything else, sidewalks and verges included, is the map's ``background``:
  ``"intermediate"`` (as :func:`dstenv.sim.osm.load_osm` rasterises an OSM file) or
  ``"none"`` (no information).

Roads win over buildings where both are drawn, as in the OSM loader.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numba
import numpy as np

from dstenv.sim.raster import fill_polygon
from dstenv.sim.types import MapClass, WorldMap

__all__ = ["draw_known_map"]


def draw_known_map(world_map: WorldMap, cfg: Mapping[str, Any], rng: np.random.Generator,
                   drop: np.ndarray) -> np.ndarray:
    """Rasterise the imperfect map of ``world_map``.

    Args:
        world_map: the true map.
        cfg: a validated ``gis`` section.
        rng: random source (draws: per kept building 3 normals, then the extra
            buildings).
        drop: indices of the missing buildings.

    Returns:
        ``(Hm, Wm) uint8`` :class:`MapClass` raster on the grid of ``world_map.raster``.
    """
    truth = np.ascontiguousarray(world_map.raster, dtype=np.uint8)
    res, org = float(world_map.resolution), world_map.origin
    by_lanes = cfg["road_width"] == "lanes" and len(world_map.streets) > 0
    out = truth.copy()
    out[out == MapClass.BUILDING] = MapClass.INTERMEDIATE
    if by_lanes:
        out[out == MapClass.ROAD] = MapClass.INTERMEDIATE
    kept = np.ones(len(world_map.buildings), bool)
    kept[np.asarray(drop, np.int64)] = False
    for b in np.flatnonzero(kept):
        poly = np.asarray(world_map.buildings[b], np.float64)
        shift = rng.normal(0.0, cfg["outline_shift_std"], 2) if cfg["outline_shift_std"] > 0 \
            else np.zeros(2)
        scale = 1.0 + (rng.normal(0.0, cfg["outline_scale_std"]) if cfg["outline_scale_std"] > 0
                       else 0.0)
        c = poly.mean(0)
        fill_polygon(out, [c + (poly - c) * max(scale, 0.5) + shift], org, res, MapClass.BUILDING)
    n_extra = rng.poisson(cfg["extra_building_rate"] * len(world_map.buildings)) \
        if cfg["extra_building_rate"] > 0 else 0
    for _ in range(n_extra):
        _extra_building(out, truth, org, res, rng)
    if by_lanes:
        for line, lanes in zip(world_map.streets, world_map.street_lanes):
            half = 0.5 * max(int(lanes), 1) * cfg["nominal_lane_width"]
            _paint_band(out, np.ascontiguousarray(line, np.float64), half, float(org[0]),
                        float(org[1]), res, np.uint8(MapClass.ROAD))
    else:
        out[truth == MapClass.ROAD] = MapClass.ROAD
    if cfg["background"] == "none":
        out[out == MapClass.INTERMEDIATE] = MapClass.NONE
    return out


def _extra_building(out: np.ndarray, truth: np.ndarray, org, res: float,
                    rng: np.random.Generator, tries: int = 20) -> None:
    """A building in the map where the world has open ground (>= 4 m from any road or
    building)."""
    h, w = truth.shape
    pad = int(math.ceil(4.0 / res))
    for _ in range(tries):
        lx, ly = rng.uniform(6.0, 18.0, 2)
        nx, ny = int(lx / res), int(ly / res)
        if nx + 2 * pad >= w or ny + 2 * pad >= h:
            return
        c0 = int(rng.integers(0, w - nx - 2 * pad))
        r0 = int(rng.integers(0, h - ny - 2 * pad))
        window = truth[r0:r0 + ny + 2 * pad, c0:c0 + nx + 2 * pad]
        if np.all(window == MapClass.INTERMEDIATE):
            out[r0 + pad:r0 + pad + ny, c0 + pad:c0 + pad + nx] = MapClass.BUILDING
            return


@numba.njit(cache=True)
def _paint_band(out, line, half, x0, y0, res, value):  # pragma: no cover - numba
    """Cells whose centre lies within ``half`` [m] of the polyline ``line (K, 2)``."""
    h, w = out.shape
    for k in range(line.shape[0] - 1):
        ax, ay, bx, by = line[k, 0], line[k, 1], line[k + 1, 0], line[k + 1, 1]
        ex, ey = bx - ax, by - ay
        ll = ex * ex + ey * ey
        c_lo = max(int(math.floor((min(ax, bx) - half - x0) / res)), 0)
        c_hi = min(int(math.ceil((max(ax, bx) + half - x0) / res)), w - 1)
        r_lo = max(int(math.floor((min(ay, by) - half - y0) / res)), 0)
        r_hi = min(int(math.ceil((max(ay, by) + half - y0) / res)), h - 1)
        for r in range(r_lo, r_hi + 1):
            yc = y0 + (r + 0.5) * res
            for c in range(c_lo, c_hi + 1):
                xc = x0 + (c + 0.5) * res
                t = 0.0 if ll == 0.0 else ((xc - ax) * ex + (yc - ay) * ey) / ll
                t = min(max(t, 0.0), 1.0)
                dx = ax + t * ex - xc
                dy = ay + t * ey - yc
                if dx * dx + dy * dy <= half * half:
                    out[r, c] = value
