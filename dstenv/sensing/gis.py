"""The GIS grid: map classes cut from the world raster in the ego frame.

Each ego-grid cell takes the :class:`dstenv.sim.types.MapClass` code of the map
raster cell containing its centre (nearest-neighbour lookup); centres outside the
raster get ``MapClass.NONE`` (0). An optional :class:`MapError` models an imperfect
map and localisation: the grid is cut at a wrong pose (offset along ego x / y and a
heading error) from a map that lacks some buildings (their cells read as
``MapClass.INTERMEDIATE``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from dstenv.grid import GridSpec
from dstenv.sensing.config import gis_config
from dstenv.sensing.mapmodel import draw_known_map
from dstenv.sim.types import MapClass, WorldMap

__all__ = ["MapError", "gis_grid", "lookup_map", "remove_buildings"]

_IDENTITY = np.arange(256, dtype=np.uint8)


@dataclass
class MapError:
    """A drawn map / localisation error, applied by :func:`gis_grid`.

    Attributes:
        offset: ``(2,) float64`` error of the believed ego position along ego x and
            ego y [m].
        rotation: error of the believed heading [rad].
        raster: ``(Hm, Wm) uint8`` the map as known (the world raster with the
            missing buildings turned into intermediate space), or ``None`` for the
            true raster.
        dropped: indices into ``WorldMap.buildings`` of the missing buildings.
        vacuous: there is no map: every GIS cell is ``MapClass.NONE``.
    """

    offset: np.ndarray
    rotation: float = 0.0
    raster: np.ndarray | None = None
    dropped: tuple[int, ...] = ()
    vacuous: bool = False

    @classmethod
    def sample(
        cls, world_map: WorldMap, config: Mapping[str, Any] | None, rng: np.random.Generator
    ) -> "MapError":
        """Draw an error from a ``gis`` config section.

        Draw once per episode for a persistently wrong map; pass a config dict to
        :func:`gis_grid` instead to redraw it at every call (localisation jitter).

        Args:
            world_map: the true map.
            config: overrides of :func:`dstenv.sensing.config.default_gis_config`.
            rng: the random source (draws: offset (2 normals), rotation (1 normal),
                one uniform per building when ``missing_building_prob > 0``, one
                uniform when ``no_map_prob > 0``, then those of
                :func:`~dstenv.sensing.mapmodel.draw_known_map` when the map differs
                from the world in more than the dropped buildings).

        Raises:
            ValueError: ``missing_building_prob > 0`` but the map has building cells
                and no building polygons to drop (a map without buildings drops none).
        """
        cfg = gis_config(config)
        offset = rng.normal(0.0, cfg["offset_std"], 2) if cfg["offset_std"] > 0 else np.zeros(2)
        rotation = float(rng.normal(0.0, cfg["rotation_std"])) if cfg["rotation_std"] > 0 else 0.0
        p = cfg["missing_building_prob"]
        drop = np.zeros(0, np.int64)
        # a map without buildings has none to drop (it used to be an error: a sparse
        # city's seed without a building stopped a generation run)
        if p > 0 and world_map.buildings:
            drop = np.flatnonzero(rng.random(len(world_map.buildings)) < p)
        elif p > 0 and (world_map.raster == MapClass.BUILDING).any():
            raise ValueError("gis.missing_building_prob > 0 needs WorldMap.buildings "
                             "polygons; the map has building cells but none")
        none = cfg["source"] == "none" or (cfg["no_map_prob"] > 0
                                           and rng.random() < cfg["no_map_prob"])
        if none:
            return cls(offset, rotation, None, (), vacuous=True)
        redraw = (cfg["road_width"] == "lanes" and len(world_map.streets) > 0) \
            or cfg["background"] != "intermediate" or cfg["extra_building_rate"] > 0 \
            or ((cfg["outline_shift_std"] > 0 or cfg["outline_scale_std"] > 0)
                and len(world_map.buildings) > 0)
        if redraw:
            raster = draw_known_map(world_map, cfg, rng, drop)
        elif len(drop):
            raster = remove_buildings(world_map, drop)
        else:
            raster = None
        return cls(offset, rotation, raster, tuple(int(b) for b in drop))


def gis_grid(
    world_map: WorldMap,
    pose: np.ndarray,
    spec: GridSpec,
    map_error: MapError | Mapping[str, Any] | None = None,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Map classes around the ego.

    Args:
        world_map: the map.
        pose: ``(3,)`` ego world pose ``(x [m], y [m], yaw [rad])``.
        spec: grid geometry (:mod:`dstenv.grid`).
        map_error: ``None`` (exact map), a drawn :class:`MapError`, or a ``gis``
            config dict from which a fresh error is drawn with ``rng``.
        rng: required when ``map_error`` is a config dict.

    Returns:
        ``(H, W) uint8`` :class:`MapClass` codes.
    """
    pose = _check_pose(pose, "gis_grid")
    raster = world_map.raster
    if isinstance(map_error, Mapping):
        if rng is None:
            raise ValueError("gis_grid: a map_error config needs an rng to draw the error from")
        map_error = MapError.sample(world_map, map_error, rng)
    if map_error is not None and map_error.vacuous:
        return np.full(spec.shape, MapClass.NONE, dtype=np.uint8)
    if map_error is not None:
        px, py, yaw = pose
        dx, dy = (float(v) for v in map_error.offset)
        c, s = math.cos(yaw), math.sin(yaw)
        pose = np.array([px + c * dx - s * dy, py + s * dx + c * dy, yaw + map_error.rotation])
        if map_error.raster is not None:
            raster = map_error.raster
    return lookup_map(raster, world_map.origin, world_map.resolution, pose, spec)


def lookup_map(
    raster: np.ndarray,
    origin: tuple[float, float],
    resolution: float,
    pose: np.ndarray,
    spec: GridSpec,
) -> np.ndarray:
    """Nearest-neighbour lookup of a world raster at every ego-cell centre.

    Args:
        raster: ``(Hm, Wm) uint8`` codes in the layout of :class:`WorldMap`.
        origin: ``(x0, y0)`` world corner of the raster [m].
        resolution: raster cell size [m].
        pose: ``(3,)`` ego world pose.
        spec: grid geometry.

    Returns:
        ``(H, W) uint8``: the raster value under each cell centre, 0 outside it.
    """
    raster = np.ascontiguousarray(raster, dtype=np.uint8)
    if raster.ndim != 2:
        raise ValueError(f"map raster must be 2-D, got shape {raster.shape}")
    if not resolution > 0:
        raise ValueError(f"map resolution must be > 0 m, got {resolution}")
    px, py, yaw = _check_pose(pose, "lookup_map")
    out = np.empty(spec.shape, dtype=np.uint8)
    _lookup(raster, float(origin[0]), float(origin[1]), float(resolution),
            px, py, yaw, float(spec.cell_size), _IDENTITY, out)
    return out


def remove_buildings(world_map: WorldMap, drop: np.ndarray) -> np.ndarray:
    """The map raster with some buildings replaced by intermediate space.

    A BUILDING cell belongs to a dropped polygon when its centre lies inside it, or
    lies within one raster cell of its outline and inside no kept polygon (so the
    rasteriser's edge cells go too, but a neighbouring building keeps its own).

    Args:
        world_map: the map (its raster is not modified).
        drop: indices into ``world_map.buildings``.

    Returns:
        ``(Hm, Wm) uint8`` a new raster.
    """
    out = np.array(world_map.raster, dtype=np.uint8, copy=True)
    polys = [np.asarray(p, dtype=np.float64) for p in world_map.buildings]
    boxes = np.array([[*p.min(0), *p.max(0)] for p in polys]).reshape(-1, 4)
    res = float(world_map.resolution)
    x0, y0 = (float(v) for v in world_map.origin)
    kept = np.ones(len(polys), dtype=bool)
    kept[np.asarray(drop, dtype=np.int64)] = False
    for b in np.asarray(drop, dtype=np.int64):
        lo = boxes[b, :2] - res
        hi = boxes[b, 2:] + res
        near = np.flatnonzero(kept & np.all(boxes[:, :2] <= hi, 1) & np.all(boxes[:, 2:] >= lo, 1))
        others = [polys[k] for k in near]
        verts = np.concatenate(others) if others else np.zeros((0, 2))
        starts = np.cumsum([0] + [len(p) for p in others]).astype(np.int64)
        c0, r0 = int(math.floor((lo[0] - x0) / res)), int(math.floor((lo[1] - y0) / res))
        c1, r1 = int(math.floor((hi[0] - x0) / res)), int(math.floor((hi[1] - y0) / res))
        _clear_polygon(out, x0, y0, res, max(r0, 0), min(r1 + 1, out.shape[0]),
                       max(c0, 0), min(c1 + 1, out.shape[1]), polys[b], verts, starts,
                       np.uint8(MapClass.BUILDING), np.uint8(MapClass.INTERMEDIATE))
    return out


def _check_pose(pose: np.ndarray, where: str) -> tuple[float, float, float]:
    p = np.asarray(pose, dtype=np.float64)
    if p.shape == (3,):
        x, y, yaw = p.tolist()  # Python floats: the finite test without numpy's overhead
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw):
            return x, y, yaw
    raise ValueError(f"{where}: pose must be a finite (3,) array (x, y, yaw), got {pose!r}")


@numba.njit(cache=True)
def _lookup(raster, x0, y0, res, px, py, yaw, c, lut, out):  # pragma: no cover - numba
    """``out[i, j] = lut[raster[cell under the centre of (i, j)]]`` (``lut[0]`` outside).

    Along a grid row the raster coordinates ``fx = bx + ax[j]``, ``fy = by + ay[j]``
    are monotone in ``j`` (float addition and multiplication by a constant are
    monotone), so the cells inside the raster form one interval: it is found by
    walking in from both ends, and the cells inside it need no bounds test (their
    coordinates are in ``[0, Wm)`` x ``[0, Hm)``, so int32 truncation is ``floor``).

    Returns the number of cells whose value became 255 (unknown codes, for callers
    whose ``lut`` flags them).
    """
    h, w = out.shape
    hm, wm = raster.shape
    flat = raster.reshape(hm * wm)
    oflat = out.reshape(h * w)
    i0 = h // 2
    j0 = w // 2
    cy = math.cos(yaw)
    sy = math.sin(yaw)
    inv = 1.0 / res
    fwm = float(wm)
    fhm = float(hm)
    if hm * wm >= 2**31:
        raise ValueError("map raster too large for the lookup (2**31 cells or more)")
    wm32 = np.int32(wm)
    q = np.empty(w, np.int32)
    # raster coordinates (column fx, row fy) are affine in the cell centre (x, y)
    ax = np.empty(w)
    ay = np.empty(w)
    for j in range(w):
        y = (j0 - j) * c
        ax[j] = -sy * y * inv
        ay[j] = cy * y * inv
    outside = lut[0]
    bad = 0
    for i in range(h):
        x = (i0 - i) * c
        bx = (px + cy * x - x0) * inv
        by = (py + sy * x - y0) * inv
        base = i * w
        lo = 0
        while lo < w:
            fx = bx + ax[lo]
            fy = by + ay[lo]
            if 0.0 <= fx < fwm and 0.0 <= fy < fhm:
                break
            oflat[base + lo] = outside
            lo += 1
        hi = w
        while hi > lo:
            fx = bx + ax[hi - 1]
            fy = by + ay[hi - 1]
            if 0.0 <= fx < fwm and 0.0 <= fy < fhm:
                break
            hi -= 1
            oflat[base + hi] = outside
        if outside == 255:
            bad += lo + w - hi
        # the raster cells of the interval: their flat indices first (a loop LLVM
        # vectorises), then the gather; slices and unsigned indices keep numba's
        # negative-index wraparound code out of both loops
        n = hi - lo
        axs = ax[lo:hi]
        ays = ay[lo:hi]
        qs = q[:n]
        for j in range(n):
            qs[j] = np.int32(by + ays[j]) * wm32 + np.int32(bx + axs[j])
        row = oflat[base + lo:base + hi]
        nb = 0
        for j in range(n):
            v = lut[flat[np.uint32(qs[j])]]
            row[j] = v
            nb += v == 255
        bad += nb
    return bad


@numba.njit(cache=True, inline="always")
def _inside(px, py, poly, a, b):  # pragma: no cover - numba
    """Even-odd test of a point against vertices ``poly[a:b]``."""
    inside = False
    j = b - 1
    for i in range(a, b):
        xi, yi = poly[i, 0], poly[i, 1]
        xj, yj = poly[j, 0], poly[j, 1]
        if (yi > py) != (yj > py) and px < (xj - xi) * (py - yi) / (yj - yi) + xi:
            inside = not inside
        j = i
    return inside


@numba.njit(cache=True)
def _clear_polygon(out, x0, y0, res, r0, r1, c0, c1, poly, others, starts,
                   building, repl):  # pragma: no cover - numba
    n = poly.shape[0]
    for r in range(r0, r1):
        yc = y0 + (r + 0.5) * res
        for col in range(c0, c1):
            if out[r, col] != building:
                continue
            xc = x0 + (col + 0.5) * res
            hit = _inside(xc, yc, poly, 0, n)
            if not hit:
                # distance from the cell centre to the outline
                d2 = np.inf
                for i in range(n):
                    ax, ay = poly[i - 1, 0], poly[i - 1, 1]
                    ex, ey = poly[i, 0] - ax, poly[i, 1] - ay
                    ll = ex * ex + ey * ey
                    t = 0.0 if ll == 0 else ((xc - ax) * ex + (yc - ay) * ey) / ll
                    t = min(max(t, 0.0), 1.0)
                    qx, qy = ax + t * ex - xc, ay + t * ey - yc
                    d2 = min(d2, qx * qx + qy * qy)
                if d2 <= res * res:
                    hit = True
                    for k in range(starts.shape[0] - 1):
                        if _inside(xc, yc, others, starts[k], starts[k + 1]):
                            hit = False
                            break
            if hit:
                out[r, col] = repl
