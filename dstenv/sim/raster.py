"""Painting geometry into map rasters (row index grows with y, see ``WorldMap``)."""

from __future__ import annotations

import threading

import numba as nb
import numpy as np

from dstenv.sim.types import MapClass, WorldMap

__all__ = ["fill_polygon", "fill_polygons", "fill_polygons_flat", "fill_rect", "fill_rects",
           "fillet_corners", "lookup", "paint_where", "scratch_raster", "Surface",
           "surface_raster"]

_SCRATCH = threading.local()  # per thread: the flat buffer behind scratch_raster


class Surface:
    """Finer surface codes of :func:`surface_raster` (drawing only)."""

    YARD = 0
    BUILDING = 1
    ROAD = 2
    SIDEWALK = 3
    PARKING = 4
    CROSSWALK = 5
    VERGE = 6  # raised grass: roundabout islands and medians


def scratch_raster(shape: tuple[int, int], value: int) -> np.ndarray:
    """A ``shape`` uint8 raster filled with ``value``, in a buffer this thread reuses.

    For a raster that lives only until the next call (the unwarped city, re-sampled
    through the warp and dropped): a fresh one of a few MB costs a page fault every
    4 KiB at each reset, a reused one only the fill. The next call overwrites it.
    """
    n = int(shape[0]) * int(shape[1])
    buf = getattr(_SCRATCH, "buf", None)
    if buf is None or buf.size < n:
        buf = _SCRATCH.buf = np.empty(n + n // 4, np.uint8)  # headroom: maps vary in size
    out = buf[:n].reshape(shape)
    out.fill(value)
    return out


@nb.njit(cache=True)
def _fill_rings(raster, xs, ys, ring_ptr, x0, y0, res, value):
    """Even-odd scanline fill of the rings ``xs/ys[ring_ptr[k]:ring_ptr[k+1]]``."""
    h, w = raster.shape
    ymin, ymax = ys.min(), ys.max()
    r_lo = max(int(np.floor((ymin - y0) / res - 0.5)), 0)
    r_hi = min(int(np.ceil((ymax - y0) / res + 0.5)), h - 1)
    cross = np.empty(xs.shape[0], np.float64)
    for r in range(r_lo, r_hi + 1):
        yc = y0 + (r + 0.5) * res
        n = 0
        for k in range(ring_ptr.shape[0] - 1):
            a, b = ring_ptr[k], ring_ptr[k + 1]
            for i in range(a, b):
                j = i + 1 if i + 1 < b else a
                ya, yb = ys[i], ys[j]
                if (ya <= yc) != (yb <= yc):
                    cross[n] = xs[i] + (yc - ya) * (xs[j] - xs[i]) / (yb - ya)
                    n += 1
        if n < 2:
            continue
        for p in range(1, n):  # insertion sort in place (a handful of crossings)
            v = cross[p]
            q = p - 1
            while q >= 0 and cross[q] > v:
                cross[q + 1] = cross[q]
                q -= 1
            cross[q + 1] = v
        row = raster[r]
        for p in range(0, n - 1, 2):
            c_lo = max(int(np.ceil((cross[p] - x0) / res - 0.5)), 0)
            c_hi = min(int(np.floor((cross[p + 1] - x0) / res - 0.5)), w - 1)
            if c_hi >= c_lo:
                row[c_lo:c_hi + 1] = value  # a run: one memset


def fill_polygon(raster: np.ndarray, rings: list[np.ndarray], origin: tuple[float, float],
                 resolution: float, value: int) -> None:
    """Set every cell whose centre lies inside a polygon (even-odd rule) to ``value``.

    Args:
        raster: ``(H, W) uint8`` raster, modified in place.
        rings: exterior and hole rings, each ``(K, 2) float64`` (closed or not).
        origin: ``(x0, y0)`` world coordinates of the raster corner [m].
        resolution: cell size [m].
        value: code to write.
    """
    rings = [np.asarray(r, np.float64) for r in rings if len(r) >= 3]
    if not rings:
        return
    xy = np.concatenate(rings)
    ptr = np.cumsum([0] + [len(r) for r in rings]).astype(np.int64)
    _fill_rings(raster, np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]), ptr,
                float(origin[0]), float(origin[1]), float(resolution), np.uint8(value))


@nb.njit(cache=True)
def _fill_each(raster, xs, ys, poly_ptr, x0, y0, res, value):  # pragma: no cover - numba
    one = np.zeros(2, np.int64)
    for k in range(poly_ptr.shape[0] - 1):
        one[0], one[1] = 0, poly_ptr[k + 1] - poly_ptr[k]
        _fill_rings(raster, xs[poly_ptr[k]:poly_ptr[k + 1]], ys[poly_ptr[k]:poly_ptr[k + 1]], one,
                    x0, y0, res, value)


def fill_polygons(raster: np.ndarray, polys: list[np.ndarray], origin: tuple[float, float],
                  resolution: float, value: int) -> None:
    """:func:`fill_polygon` of many simple polygons (each ``(K, 2)``, no holes) in one
    call (a city's buildings), in place."""
    polys = [np.asarray(p, np.float64) for p in polys if len(p) >= 3]
    if not polys:
        return
    ptr = np.cumsum([0] + [len(p) for p in polys]).astype(np.int64)
    fill_polygons_flat(raster, np.concatenate(polys), ptr, origin, resolution, value)


def fill_polygons_flat(raster: np.ndarray, xy: np.ndarray, ptr: np.ndarray,
                       origin: tuple[float, float], resolution: float, value: int) -> None:
    """:func:`fill_polygons` of flat vertices: polygon ``k`` is ``xy[ptr[k]:ptr[k + 1]]``.

    Args:
        raster: ``(H, W) uint8``, modified in place.
        xy: ``(V, 2) float64`` vertices [m]; ptr: ``(P + 1,) int64`` offsets, each
            polygon with >= 3 vertices.
        origin, resolution, value: as for :func:`fill_polygon`.
    """
    if len(ptr) < 2:
        return
    xy = np.asarray(xy, np.float64)
    _fill_each(raster, np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
               np.asarray(ptr, np.int64), float(origin[0]), float(origin[1]), float(resolution),
               np.uint8(value))


def fill_rect(raster: np.ndarray, x_lo: float, x_hi: float, y_lo: float, y_hi: float,
              origin: tuple[float, float], resolution: float, value: int) -> None:
    """Set the cells whose centres lie in the axis-aligned box to ``value`` (in place)."""
    _fill_box(raster, float(x_lo), float(x_hi), float(y_lo), float(y_hi), float(origin[0]),
              float(origin[1]), float(resolution), np.uint8(value))


def fill_rects(raster: np.ndarray, boxes: np.ndarray, origin: tuple[float, float],
               resolution: float, value: int) -> None:
    """:func:`fill_rect` of every row ``x_lo, x_hi, y_lo, y_hi`` of ``boxes (N, 4)``
    [m], in order, in one call."""
    _fill_boxes(raster, np.ascontiguousarray(boxes, np.float64).reshape(-1, 4),
                float(origin[0]), float(origin[1]), float(resolution), np.uint8(value))


@nb.njit(cache=True)
def _fill_box(raster, x_lo, x_hi, y_lo, y_hi, x0, y0, res, value):  # pragma: no cover
    h, w = raster.shape
    c_lo = max(int(np.ceil((x_lo - x0) / res - 0.5)), 0)
    c_hi = min(int(np.floor((x_hi - x0) / res - 0.5)), w - 1)
    r_lo = max(int(np.ceil((y_lo - y0) / res - 0.5)), 0)
    r_hi = min(int(np.floor((y_hi - y0) / res - 0.5)), h - 1)
    if c_hi >= c_lo and r_hi >= r_lo:
        raster[r_lo:r_hi + 1, c_lo:c_hi + 1] = value


@nb.njit(cache=True)
def _fill_boxes(raster, boxes, x0, y0, res, value):  # pragma: no cover - numba
    for i in range(boxes.shape[0]):
        _fill_box(raster, boxes[i, 0], boxes[i, 1], boxes[i, 2], boxes[i, 3], x0, y0, res,
                  value)


def paint_where(dst: np.ndarray, src: np.ndarray, code: int, value: int) -> None:
    """``dst[src == code] = value`` in place, in one pass without temporaries.

    Args:
        dst, src: ``(H, W) uint8`` rasters of one grid (``dst`` C-contiguous).
    """
    if not dst.flags.c_contiguous:
        raise ValueError("paint_where: dst must be C-contiguous")
    _paint_where(dst.reshape(-1), np.ascontiguousarray(src).reshape(-1), np.uint8(code),
                 np.uint8(value))


@nb.njit(cache=True)
def _paint_where(dst, src, code, value):  # pragma: no cover - numba
    for i in range(src.shape[0]):
        dst[i] = value if src[i] == code else dst[i]


def lookup(world_map: WorldMap, xy: np.ndarray) -> np.ndarray:
    """Map classes under world points; :attr:`MapClass.NONE` outside the raster.

    Args:
        world_map: the map.
        xy: ``(..., 2) float64`` world points [m].

    Returns:
        ``(...) uint8`` :class:`MapClass` codes.
    """
    xy = np.asarray(xy, np.float64)
    x0, y0 = world_map.origin
    c = np.floor((xy[..., 0] - x0) / world_map.resolution).astype(np.int64)
    r = np.floor((xy[..., 1] - y0) / world_map.resolution).astype(np.int64)
    h, w = world_map.raster.shape
    ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
    out = np.full(c.shape, MapClass.NONE, np.uint8)
    out[ok] = world_map.raster[r[ok], c[ok]]
    return out


def fillet_corners(raster: np.ndarray, surface: np.ndarray, face: tuple[float, ...], r: float,
                   res: float) -> None:
    """Round the kerb at the four corners of a block ``face = (x0, x1, y0, y1)`` [m]
    (radius ``r`` [m]): the cut-off corners become road in both rasters (origin
    ``(0, 0)``, cell size ``res``), in place. A cell is cut off when its centre lies
    inside the block, in the corner's ``r x r`` square and outside the circle of radius
    ``r`` centred ``(r, r)`` into the block."""
    _fillet_corners(raster, surface, *(float(v) for v in face), float(r), float(res),
                    np.uint8(MapClass.ROAD), np.uint8(Surface.ROAD))


@nb.njit(cache=True)
def _fillet_corners(raster, surface, x0, x1, y0, y1, r, res, road, s_road):  # pragma: no cover
    h, w = raster.shape
    corners = ((x0, y0, 1, 1), (x1, y0, -1, 1), (x0, y1, 1, -1), (x1, y1, -1, -1))
    for k in range(4):
        cx, cy, sx, sy = corners[k]
        ox, oy = cx + sx * r, cy + sy * r
        c_lo, c_hi = int(np.floor(min(cx, ox) / res)), int(np.ceil(max(cx, ox) / res))
        r_lo, r_hi = int(np.floor(min(cy, oy) / res)), int(np.ceil(max(cy, oy) / res))
        for row in range(max(r_lo, 0), min(r_hi, h)):
            yc = (row + 0.5) * res
            if not ((yc - cy) * sy >= 0 and (yc - oy) * sy < 0):
                continue
            for col in range(max(c_lo, 0), min(c_hi, w)):
                xc = (col + 0.5) * res
                if ((xc - cx) * sx >= 0 and (xc - ox) * sx < 0
                        and (xc - ox) ** 2 + (yc - oy) ** 2 > r * r):
                    raster[row, col] = road
                    surface[row, col] = s_road


def surface_raster(world_map: WorldMap) -> np.ndarray | None:
    """The drawing-only :class:`Surface` raster of a map, on the grid of its raster:
    ``(Hm, Wm) uint8``, or None when the map has none.

    A warped city keeps its unwarped surface (``meta["surface_source"]``): nothing in
    an episode reads it, and re-sampling it would cost a third of the warp. It is
    warped here at the first call, with the buildings of ``world_map.raster`` painted
    in, and kept as ``meta["surface"]``.
    """
    meta = world_map.meta
    if "surface" not in meta and "surface_source" in meta:
        src = meta.pop("surface_source")
        out = meta["warp"].raster(src, world_map.raster.shape, world_map.resolution,
                                  Surface.YARD)
        paint_where(out, world_map.raster, MapClass.BUILDING, Surface.BUILDING)
        meta["surface"] = out
    return meta.get("surface")
