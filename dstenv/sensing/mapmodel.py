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
import weakref
from collections.abc import Mapping
from typing import Any

import numba
import numpy as np

from dstenv.sim.raster import fill_polygons_flat, paint_where
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

    The first draw of a map paints in that order (class remap, buildings, roads);
    later draws of the same map (a map pool, ``keep_map``) copy a cached base that
    holds the remap and the roads, paint the buildings and then the roads again from
    the base's road runs: the same raster, without the two passes over it.
    """
    truth = np.ascontiguousarray(world_map.raster, dtype=np.uint8)
    res, org = float(world_map.resolution), world_map.origin
    by_lanes = cfg["road_width"] == "lanes" and len(world_map.streets) > 0
    key = (id(world_map.raster), by_lanes, cfg["background"], cfg["nominal_lane_width"])
    seen = _BASES.get(id(world_map))
    if seen is None:
        weakref.finalize(world_map, _BASES.pop, id(world_map), None)
    if seen is None or seen[0] != key:  # first draw: no base (a fresh map is drawn once)
        _BASES[id(world_map)] = (key, None)
        out = _remap_classes(truth, cfg, by_lanes)
        runs = None
    else:
        if seen[1] is None:
            base = _remap_classes(truth, cfg, by_lanes)
            _paint_roads(base, world_map, truth, cfg, by_lanes)
            base.flags.writeable = False
            _BASES[id(world_map)] = (key, (base, _runs(base, np.uint8(MapClass.ROAD))))
        base, runs = _BASES[id(world_map)][1]
        out = base.copy()
    kept = np.ones(len(world_map.buildings), bool)
    kept[np.asarray(drop, np.int64)] = False
    xy, ptr = _moved_outlines(_outline_table(world_map), np.flatnonzero(kept), cfg, rng)
    fill_polygons_flat(out, xy, ptr, org, res, MapClass.BUILDING)
    n_extra = rng.poisson(cfg["extra_building_rate"] * len(world_map.buildings)) \
        if cfg["extra_building_rate"] > 0 else 0
    _extra_buildings(out, truth, res, rng, int(n_extra))
    if runs is None:
        _paint_roads(out, world_map, truth, cfg, by_lanes)
    else:
        _paint_runs(out, runs, np.uint8(MapClass.ROAD))
    return out


#: per live map (by ``id``): ``(key, None)`` after its first draw, ``(key, (base,
#: road runs))`` from its second (see :func:`draw_known_map`); ``key`` holds the
#: raster object and the ``gis`` keys the base depends on (a map's raster and
#: streets do not change after it is built)
_BASES: dict[int, tuple[tuple[Any, ...], tuple[np.ndarray, np.ndarray] | None]] = {}


def _remap_classes(truth: np.ndarray, cfg: Mapping[str, Any], by_lanes: bool) -> np.ndarray:
    """What the map knows before anything is drawn: ``(Hm, Wm) uint8``. Buildings (and,
    drawn by lanes, roads) become the background, as do the unknown open spaces."""
    bg = MapClass.NONE if cfg["background"] == "none" else MapClass.INTERMEDIATE
    lut = np.arange(4, dtype=np.uint8)
    lut[[MapClass.BUILDING, MapClass.INTERMEDIATE]] = bg
    if by_lanes:
        lut[MapClass.ROAD] = bg
    return _remap(truth, lut)


def _paint_roads(out: np.ndarray, world_map: WorldMap, truth: np.ndarray,
                 cfg: Mapping[str, Any], by_lanes: bool) -> None:
    """Roads over ``out``, in place: street bands of ``lanes x nominal_lane_width``
    (``by_lanes``), else the true road cells."""
    if by_lanes:
        res, org = float(world_map.resolution), world_map.origin
        lines = [np.asarray(line, np.float64) for line in world_map.streets]
        half = np.array([0.5 * max(int(n), 1) * cfg["nominal_lane_width"]
                         for n in world_map.street_lanes], np.float64)
        line_ptr = np.cumsum([0] + [len(line) for line in lines]).astype(np.int64)
        _paint_bands(out, np.concatenate(lines), line_ptr, half, float(org[0]), float(org[1]),
                     res, np.uint8(MapClass.ROAD))
    else:
        paint_where(out, truth, MapClass.ROAD, MapClass.ROAD)


@numba.njit(cache=True)
def _runs(a, value):  # pragma: no cover - numba
    """``(N, 3) int64`` rows ``row, c0, c1``: the runs ``a[row, c0:c1] == value``."""
    h, w = a.shape
    n = 0
    out = np.empty((1024, 3), np.int64)
    for r in range(h):
        row = a[r]
        c0 = -1  # start of the open run (-1: none)
        for c in range(w + 1):
            on = c < w and row[c] == value
            if on == (c0 >= 0):
                continue
            if on:
                c0 = c
                continue
            if n == out.shape[0]:
                grown = np.empty((2 * n, 3), np.int64)
                grown[:n] = out
                out = grown
            out[n, 0], out[n, 1], out[n, 2] = r, c0, c
            n += 1
            c0 = -1
    return out[:n].copy()


@numba.njit(cache=True)
def _paint_runs(out, runs, value):  # pragma: no cover - numba
    """``out[row, c0:c1] = value`` for every row of ``runs``."""
    for k in range(runs.shape[0]):
        out[runs[k, 0], runs[k, 1]:runs[k, 2]] = value


#: per live map (by ``id``): ``(buildings list, table)`` of :func:`_outline_table`
_OUTLINES: dict[int, tuple[list[np.ndarray], tuple[np.ndarray, ...]]] = {}


def _outline_table(world_map: WorldMap) -> tuple[np.ndarray, ...]:
    """All building outlines of a map, flat, with their vertex means (kept per map).

    Returns:
        ``xy (V, 2) float64`` vertices, ``ptr (P + 1,) int64`` offsets (outline ``k``
        is ``xy[ptr[k]:ptr[k + 1]]``), ``cnt (P,) int64`` vertex counts and ``centre
        (P, 2) float64`` vertex means, summed vertex by vertex as ``poly.mean(0)``
        sums (bit-identical; 0 for outlines of < 3 vertices, which are not drawn).
    """
    hit = _OUTLINES.get(id(world_map))
    if hit is not None and hit[0] is world_map.buildings:
        return hit[1]
    polys = [np.asarray(p, np.float64).reshape(-1, 2) for p in world_map.buildings]
    cnt = np.array([len(p) for p in polys], np.int64)
    ptr = np.concatenate([[0], np.cumsum(cnt)]).astype(np.int64)
    xy = np.concatenate(polys) if polys else np.zeros((0, 2))
    centre = np.zeros((len(polys), 2))
    ok = cnt >= 3
    for j in range(int(cnt.max()) if len(cnt) else 0):
        take = ok & (j < cnt)
        centre += np.where(take[:, None], xy[np.minimum(ptr[:-1] + j, max(len(xy) - 1, 0))],
                           0.0)
    centre[ok] /= cnt[ok, None]
    if hit is None:
        weakref.finalize(world_map, _OUTLINES.pop, id(world_map), None)
    _OUTLINES[id(world_map)] = (world_map.buildings, (xy, ptr, cnt, centre))
    return _OUTLINES[id(world_map)][1]


def _moved_outlines(table: tuple[np.ndarray, ...], kept: np.ndarray, cfg: Mapping[str, Any],
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Building outlines shifted and scaled about their vertex mean, as traced.

    Args:
        table: the map's :func:`_outline_table`.
        kept: ``(n,) int64`` indices of the buildings in the map, in order.

    Draws per kept outline (in order) 2 normals of the shift, then 1 of the scale
    (each only when its std > 0). Returns ``xy (V, 2) float64`` and ``ptr (P + 1,)
    int64``: outline ``k`` is ``xy[ptr[k]:ptr[k + 1]]``; outlines of < 3 vertices are
    left out.
    """
    xy_all, ptr_all, cnt_all, centre = table
    shift_std, scale_std = cfg["outline_shift_std"], cfg["outline_scale_std"]
    n = len(kept)
    z = rng.standard_normal((n, int(shift_std > 0) * 2 + int(scale_std > 0)))
    # == rng.normal(0, std) per building: loc + scale * standard normal
    shift = shift_std * z[:, :2] if shift_std > 0 else np.zeros((n, 2))
    scale = 1.0 + (scale_std * z[:, -1] if scale_std > 0 else np.zeros(n))
    valid = cnt_all[kept] >= 3
    sel = kept[valid]
    if not len(sel):
        return np.zeros((0, 2)), np.zeros(1, np.int64)
    shift, scale = shift[valid], np.maximum(scale[valid], 0.5)
    cnt = cnt_all[sel]
    ptr = np.concatenate([[0], np.cumsum(cnt)]).astype(np.int64)
    xy = xy_all[np.repeat(ptr_all[sel] - ptr[:-1], cnt) + np.arange(ptr[-1])]
    c_v = np.repeat(centre[sel], cnt, 0)
    xy = c_v + (xy - c_v) * np.repeat(scale, cnt)[:, None] + np.repeat(shift, cnt, 0)
    return xy, ptr


@numba.njit(cache=True)
def _extra_buildings(out, truth, res, rng, n, tries=20):  # pragma: no cover - numba
    """``n`` buildings in the map where the world has open ground (>= 4 m from any road
    or building): per building up to ``tries`` drawn boxes (2 uniform sizes, then the
    column and row of the corner; numba draws these from ``rng``'s own stream exactly
    as numpy would), the first box on open ground is painted."""
    h, w = truth.shape
    pad = int(math.ceil(4.0 / res))
    open_ground = np.uint8(MapClass.INTERMEDIATE)
    for _ in range(n):
        for _ in range(tries):
            size = rng.uniform(6.0, 18.0, 2)
            nx, ny = int(size[0] / res), int(size[1] / res)
            if nx + 2 * pad >= w or ny + 2 * pad >= h:
                break
            c0 = rng.integers(0, w - nx - 2 * pad)
            r0 = rng.integers(0, h - ny - 2 * pad)
            if _all_equal(truth, r0, r0 + ny + 2 * pad, c0, c0 + nx + 2 * pad, open_ground):
                out[r0 + pad:r0 + pad + ny, c0 + pad:c0 + pad + nx] = np.uint8(MapClass.BUILDING)
                break


@numba.njit(cache=True)
def _remap(truth, lut):  # pragma: no cover - numba
    """``lut[truth]`` of a ``(H, W) uint8`` raster whose ``lut`` differs from the
    identity only at codes 1, 2, 3 (selects, which vectorise, instead of a gather)."""
    out = np.empty_like(truth)
    t, o = truth.ravel(), out.ravel()
    b, rd, it = lut[1], lut[2], lut[3]
    for i in range(t.shape[0]):
        v = t[i]
        o[i] = b if v == 1 else (rd if v == 2 else (it if v == 3 else v))
    return out


@numba.njit(cache=True)
def _all_equal(a, r0, r1, c0, c1, value):  # pragma: no cover - numba
    """``(a[r0:r1, c0:c1] == value).all()``, stopping at the first other cell."""
    for r in range(r0, r1):
        for c in range(c0, c1):
            if a[r, c] != value:
                return False
    return True


_SLACK = 1e-3  # [m] band around a street's edge where cells get the exact distance test


@numba.njit(cache=True)
def _capsule_rows(ax, ay, bx, by, rad, ys):  # pragma: no cover - numba
    """``lo, hi (R,) float64``: the x-interval [m] of each line ``y = ys[i]`` within
    ``rad`` of the segment ``a-b`` (``lo > hi``: none). The union of the two end discs
    and the rectangle between them, each crossing computed without ill-conditioned
    divisions (error ~1e-8 m)."""
    n = ys.shape[0]
    lo = np.full(n, np.inf)
    hi = np.full(n, -np.inf)
    for px, py in ((ax, ay), (bx, by)):
        for i in range(n):
            d = ys[i] - py
            if abs(d) <= rad:
                half_w = math.sqrt(rad * rad - d * d)
                lo[i] = min(lo[i], px - half_w)
                hi[i] = max(hi[i], px + half_w)
    ex, ey = bx - ax, by - ay
    ln = math.sqrt(ex * ex + ey * ey)
    if ln > 0.0:
        nx, ny = -ey / ln * rad, ex / ln * rad
        qx = np.array([ax + nx, bx + nx, bx - nx, ax - nx])
        qy = np.array([ay + ny, by + ny, by - ny, ay - ny])
        for k in range(4):
            j = (k + 1) % 4
            if qy[k] == qy[j]:
                continue
            slope = (qx[j] - qx[k]) / (qy[j] - qy[k])
            y_lo, y_hi = min(qy[k], qy[j]), max(qy[k], qy[j])
            for i in range(n):
                if y_lo <= ys[i] <= y_hi:
                    x = qx[k] + (ys[i] - qy[k]) * slope
                    lo[i] = min(lo[i], x)
                    hi[i] = max(hi[i], x)
    return lo, hi


@numba.njit(cache=True)
def _paint_bands(out, pts, ptr, halves, x0, y0, res, value):  # pragma: no cover - numba
    """Cells whose centre lies within ``halves[k]`` [m] of the polyline
    ``pts[ptr[k]:ptr[k + 1]]`` (``(V, 2) float64``), for every line ``k``.

    Per segment and row, cells whose centres lie within ``half - _SLACK`` are painted
    outright, cells beyond ``half + _SLACK`` are skipped, and the few in between get
    the exact test ``distance^2 <= half^2`` that decides every cell (same result as
    testing every cell; the interval arithmetic errs by ~1e-8 m << ``_SLACK``).
    """
    h, w = out.shape
    for li in range(ptr.shape[0] - 1):
        half = halves[li]
        hh = half * half
        r_in, r_out = half - _SLACK, half + _SLACK
        for k in range(ptr[li], ptr[li + 1] - 1):
            ax, ay, bx, by = pts[k, 0], pts[k, 1], pts[k + 1, 0], pts[k + 1, 1]
            ex, ey = bx - ax, by - ay
            ll = ex * ex + ey * ey
            r_lo = max(int(math.floor((min(ay, by) - r_out - y0) / res)), 0)
            r_hi = min(int(math.ceil((max(ay, by) + r_out - y0) / res)), h - 1)
            if r_hi < r_lo:
                continue
            ys = y0 + (np.arange(r_lo, r_hi + 1) + 0.5) * res
            o_lo, o_hi = _capsule_rows(ax, ay, bx, by, r_out, ys)
            if r_in > 0.0:
                i_lo, i_hi = _capsule_rows(ax, ay, bx, by, r_in, ys)
            else:
                i_lo, i_hi = o_hi, o_lo
            for q in range(ys.shape[0]):
                if o_lo[q] > o_hi[q]:
                    continue
                r, yc = r_lo + q, ys[q]
                c_lo = max(int(math.ceil((o_lo[q] - x0) / res - 0.5)), 0)
                c_hi = min(int(math.floor((o_hi[q] - x0) / res - 0.5)), w - 1)
                p_lo, p_hi = c_hi + 1, c_hi  # run painted outright (cells inside r_in)
                if i_lo[q] <= i_hi[q]:
                    p_lo = max(int(math.ceil((i_lo[q] - x0) / res - 0.5)), c_lo)
                    p_hi = min(int(math.floor((i_hi[q] - x0) / res - 0.5)), c_hi)
                out[r, p_lo:p_hi + 1] = value
                _test_cells(out, r, c_lo, min(p_lo, c_hi + 1), yc, ax, ay, ex, ey, ll, hh, x0,
                            res, value)
                _test_cells(out, r, max(p_hi + 1, c_lo), c_hi + 1, yc, ax, ay, ex, ey, ll, hh,
                            x0, res, value)


@numba.njit(cache=True, inline="always")
def _test_cells(out, r, c0, c1, yc, ax, ay, ex, ey, ll, hh, x0, res, value
                ):  # pragma: no cover - numba
    """The exact test of cells ``out[r, c0:c1]``: centre within ``sqrt(hh)`` of the
    segment ``a, a + e`` (``ll = |e|^2``)."""
    for c in range(c0, c1):
        xc = x0 + (c + 0.5) * res
        t = 0.0 if ll == 0.0 else ((xc - ax) * ex + (yc - ay) * ey) / ll
        t = min(max(t, 0.0), 1.0)
        dx = ax + t * ex - xc
        dy = ay + t * ey - yc
        if dx * dx + dy * dy <= hh:
            out[r, c] = value
