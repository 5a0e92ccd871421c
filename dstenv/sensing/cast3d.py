"""Exact beam casting of the 3-D LIDAR (:mod:`dstenv.sensing.lidar3d`): boxes, walls, ground.

Conventions. Column ``j`` starts at the world point ``(ox[j], oy[j])`` (the sensor
at its firing time) and runs along ``(ux[j], uy[j])``; ``t`` is the horizontal
distance along it. Channel ``c``'s beam is at height ``z(t) = mount + slope[c] t``
(``slope`` strictly decreasing in ``c``). The kernels lower ``best[j, c]`` (the
nearest ``t`` so far) and record the surface code and occluder index, in place; the
nearest hit wins, and of equal ones the first found (boxes in table order, then
walls, then the ground).

Speed (64 x 2048 beams per sweep, hundreds of occluders) comes from three
restrictions, each a superset of the beams that can hit, so the results are those
of testing every beam against every occluder:

* Columns by azimuth (:func:`column_index`): the columns are sorted by world
  azimuth once per sweep. An occluder within ``radius`` of its centre is tested
  only against the columns whose direction lies within
  ``asin(radius / (d - drift)) + asin(drift / d)`` of its bearing from the
  first column's origin (``d`` its distance, ``drift`` how far the sensor moves
  during the turn), plus one column either side; near ones (``d <= 1.5 radius +
  drift``) against all columns.
* Channels by slope: a column meets an extruded shape over ``[t_in, t_out] x
  [z_lo, z_hi]``; a beam can only hit it if its slope lies between the slopes from
  the sensor to that rectangle's corners (binary search, one channel of margin).
* Ground by distance: between the kerb top and the road a beam walks the raster
  cell by cell (Amanatides-Woo) only near raised cells; elsewhere it jumps by the
  distance to the nearest raised cell (:func:`dstenv.sensing.raised.raised_distance`,
  a lower bound from the chessboard distance over blocks of cells, two passes per
  map); the stretch of a column's ray that one such read clears serves the column's
  other channels.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["column_index", "cast_boxes", "cast_walls", "cast_ground"]


def column_index(ox: np.ndarray, oy: np.ndarray, world_az: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """Columns sorted by world azimuth, for the azimuth culling.

    Args:
        ox, oy: ``(J,) float64`` column origins [m]; world_az: ``(J,)`` directions [rad].

    Returns:
        ``(order, sorted_az, ref_x, ref_y, drift)``: ``(J,) int64`` column order,
        ``(J,) float64`` azimuths in [-pi, pi) in that order, the reference origin
        (column 0's) and the largest distance of any origin from it [m].
    """
    wrapped = np.mod(world_az + math.pi, 2 * math.pi) - math.pi
    order = np.argsort(wrapped, kind="stable")
    drift = float(np.hypot(ox - ox[0], oy - oy[0]).max()) if len(ox) else 0.0
    return order, np.ascontiguousarray(wrapped[order]), float(ox[0]), float(oy[0]), drift


@numba.njit(cache=True)
def _span(cx, cy, rad, rx, ry, drift, h_max, az):  # pragma: no cover - numba
    """Up to two ``[p0, p1)`` ranges of sorted-column positions that may see the disc."""
    n = az.shape[0]
    dx = cx - rx
    dy = cy - ry
    d = math.sqrt(dx * dx + dy * dy)
    if d - drift > math.sqrt((h_max + rad) ** 2 + rad * rad):
        return 0, 0, 0, 0
    if d <= 1.5 * rad + drift + 1e-6:
        return 0, n, 0, 0
    half = math.asin(min(1.0, rad / (d - drift))) + math.asin(min(1.0, drift / d)) + 1e-9
    if half >= math.pi:
        return 0, n, 0, 0
    a = math.atan2(dy, dx)
    lo = a - half
    hi = a + half
    if lo < -math.pi:
        return (0, min(np.searchsorted(az, hi, side="right") + 1, n),
                max(np.searchsorted(az, lo + 2 * math.pi) - 1, 0), n)
    if hi >= math.pi:
        return (max(np.searchsorted(az, lo) - 1, 0), n,
                0, min(np.searchsorted(az, hi - 2 * math.pi, side="right") + 1, n))
    return (max(np.searchsorted(az, lo) - 1, 0),
            min(np.searchsorted(az, hi, side="right") + 1, n), 0, 0)


@numba.njit(cache=True, inline="always")
def _channels(neg_slope, s_lo, s_hi):  # pragma: no cover - numba
    """``[c0, c1)``: channels whose slope may lie in ``[s_lo, s_hi]`` (``neg_slope``
    = -slope, increasing), one channel of margin either side."""
    n = neg_slope.shape[0]
    c0 = max(np.searchsorted(neg_slope, -s_hi) - 1, 0)
    c1 = min(np.searchsorted(neg_slope, -s_lo, side="right") + 1, n)
    return c0, c1


@numba.njit(cache=True, inline="always")
def _slab(p, d, half, t0, t1):  # pragma: no cover - numba
    """Clip ``[t0, t1]`` to the slab ``|p + t d| <= half``; ok = not empty."""
    if abs(d) < 1e-12:
        return t0, t1, abs(p) <= half
    a = (-half - p) / d
    b = (half - p) / d
    return max(t0, min(a, b)), min(t1, max(a, b)), True


@numba.njit(cache=True, inline="always")
def _visible(cx, cy, radius, ox, oy, ux, uy, h_max):  # pragma: no cover - numba
    """Can the column (origin o, direction u) pass within ``radius`` of (cx, cy)?"""
    dx = cx - ox
    dy = cy - oy
    along = dx * ux + dy * uy
    if along < -radius or along > h_max + radius:
        return False
    across = -dx * uy + dy * ux
    return abs(across) <= radius


@numba.njit(cache=True)
def cast_boxes(boxes, order, az, rx, ry, drift, ox, oy, ux, uy, slope, neg_slope, mount, h_max,
               best, surf, idx):  # pragma: no cover - numba
    """Extruded oriented boxes ``(K, 11)`` (rows ``cx, cy, cos, sin, half_l, half_w, z_lo,
    z_hi, surface, index, radius``): the first t of the slab interval with z in
    [z_lo, z_hi] (side face, roof, or underside of a crown)."""
    for k in range(boxes.shape[0]):
        cx, cy, rad = boxes[k, 0], boxes[k, 1], boxes[k, 10]
        p0, p1, p2, p3 = _span(cx, cy, rad, rx, ry, drift, h_max, az)
        for q in range(p0, p1 + p3 - p2):
            j = order[q] if q < p1 else order[q - p1 + p2]
            if not _visible(cx, cy, rad, ox[j], oy[j], ux[j], uy[j], h_max):
                continue
            ca, sa = boxes[k, 2], boxes[k, 3]
            px = ca * (ox[j] - cx) + sa * (oy[j] - cy)  # origin in the box frame
            py = -sa * (ox[j] - cx) + ca * (oy[j] - cy)
            dx = ca * ux[j] + sa * uy[j]
            dy = -sa * ux[j] + ca * uy[j]
            t0, t1, ok = _slab(px, dx, boxes[k, 4], -np.inf, np.inf)
            t0, t1, ok2 = _slab(py, dy, boxes[k, 5], t0, t1)
            if not (ok and ok2) or t1 < t0 or t0 < 0.0:
                continue  # missed, or the sensor is inside the box
            zlo, zhi = boxes[k, 6], boxes[k, 7]
            if t0 > 1e-9 and t1 < np.inf:
                lo = min((zlo - mount) / t0, (zlo - mount) / t1)
                hi = max((zhi - mount) / t0, (zhi - mount) / t1)
                c0, c1 = _channels(neg_slope, lo, hi)
            else:
                c0, c1 = 0, slope.shape[0]
            for c in range(c0, c1):
                if t0 >= best[j, c]:
                    continue
                z0 = mount + slope[c] * t0
                if zlo <= z0 <= zhi:
                    t = t0  # side face
                elif z0 > zhi and slope[c] < 0:
                    t = (zhi - mount) / slope[c]  # roof
                elif z0 < zlo and slope[c] > 0:
                    t = (zlo - mount) / slope[c]  # underside (a tree crown)
                else:
                    continue
                if t <= t1 and t < best[j, c]:
                    best[j, c] = t
                    surf[j, c] = int(boxes[k, 8])
                    idx[j, c] = int(boxes[k, 9])


@numba.njit(cache=True)
def cast_walls(edges, starts, circles, heights, surface, order, az, rx, ry, drift, ox, oy, ux,
               uy, slope, neg_slope, mount, h_max, best, surf, idx):  # pragma: no cover
    """Building walls: edges ``(E, 4)`` of building ``b`` in ``starts[b]:starts[b+1]``,
    bounding circles ``(B, 3)``; an edge crossed at t with z(t) in [0, heights[b]].

    A building at least as tall as the mount is met first at its nearest crossing by
    every channel that meets it at all (a beam with z in [0, h] at a farther crossing
    is between the mount height and that z at the nearer one: in [0, h] too, with
    rounding monotone in t), so only that crossing's channels are walked; a lower
    one walks every crossing."""
    for b in range(circles.shape[0]):
        cx, cy, rad = circles[b, 0], circles[b, 1], circles[b, 2]
        h = heights[b]
        nearest_only = h >= mount
        p0, p1, p2, p3 = _span(cx, cy, rad, rx, ry, drift, h_max, az)
        for q in range(p0, p1 + p3 - p2):
            j = order[q] if q < p1 else order[q - p1 + p2]
            if not _visible(cx, cy, rad, ox[j], oy[j], ux[j], uy[j], h_max):
                continue
            t_min = np.inf
            for e in range(starts[b], starts[b + 1]):
                ax = edges[e, 0] - ox[j]
                ay = edges[e, 1] - oy[j]
                ex = edges[e, 2] - edges[e, 0]
                ey = edges[e, 3] - edges[e, 1]
                den = ux[j] * ey - uy[j] * ex
                if den == 0.0:
                    continue
                t = (ax * ey - ay * ex) / den
                sp = (ax * uy[j] - ay * ux[j]) / den
                if t < 0.0 or sp < 0.0 or sp > 1.0:
                    continue
                if nearest_only:
                    t_min = min(t_min, t)
                else:
                    _wall_hits(t, h, b, j, surface, slope, neg_slope, mount, best, surf, idx)
            if t_min < np.inf:
                _wall_hits(t_min, h, b, j, surface, slope, neg_slope, mount, best, surf, idx)


@numba.njit(cache=True, inline="always")
def _wall_hits(t, h, b, j, surface, slope, neg_slope, mount, best, surf, idx):  # pragma: no cover
    """Column ``j`` crosses a wall of building ``b`` (height ``h``) at ``t``: the channels
    with z(t) in [0, h] that have nothing nearer."""
    if t > 1e-9:
        c0, c1 = _channels(neg_slope, -mount / t, (h - mount) / t)
    else:
        c0, c1 = 0, slope.shape[0]
    for c in range(c0, c1):
        z = mount + slope[c] * t
        if t < best[j, c] and 0.0 <= z <= h:
            best[j, c] = t
            surf[j, c] = surface
            idx[j, c] = b


@numba.njit(cache=True)
def cast_ground(raster, dist, shift, raised, x0, y0, res, kerb, ox, oy, ux, uy, slope, mount,
                h_max, best, surf, idx):  # pragma: no cover - numba
    """The road (z = 0, surface 0) and ``raised`` raster cells (z = ``kerb``, surface 1):
    the first raised cell met while the beam is between the kerb top and the road,
    else the road. ``dist`` from :func:`dstenv.sensing.raised.raised_distance` with the
    same ``shift`` lets the walk jump: from a point of a cell whose block reads
    ``dist = e`` no raised cell lies within ``d = e << shift`` cells, so the walk moves
    ``d`` cells (less a micrometre) at once, and steps cell by cell only where
    ``d = 0``. Such a read also clears ``d`` cells *behind* the point, and the channels
    of a column share its ray: a later channel whose whole band lies in the stretch
    cleared by an earlier one's read is road without a read (a quarter of the pass on
    the bench world; the same results)."""
    hm, wm = raster.shape
    n = slope.shape[0]
    t_top = np.empty(n)  # where each beam sinks below the kerb top, and meets the road
    t_road = np.empty(n)
    for c in range(n):
        t_top[c] = (kerb - mount) / slope[c] if slope[c] < 0.0 else np.inf
        t_road[c] = -mount / slope[c] if slope[c] < 0.0 else np.inf
    # per column, once a sweep: divisions in the beam loop cost more than its lookups
    inv_res = 1.0 / res
    tdcs = np.empty(ux.shape[0])
    tdrs = np.empty(ux.shape[0])
    for j in range(ux.shape[0]):
        tdcs[j] = res / abs(ux[j]) if ux[j] != 0.0 else np.inf
        tdrs[j] = res / abs(uy[j]) if uy[j] != 0.0 else np.inf
    # column by column: a column's row of ``best`` is contiguous, and the raster cells
    # of its channels stay cached for the next column (measured faster than channel
    # by channel, whose ``best`` reads stride a row apart)
    for j in range(ux.shape[0]):
        # a stretch [lo_ok, hi_ok] of this column's ray known to hold no raised cell (a
        # jump's reach either side of where ``dist`` was read): the channels share the
        # ray, so a band inside it is road without a lookup of its own
        lo_ok = np.inf
        hi_ok = -np.inf
        for c in range(n):
            if slope[c] >= 0.0 or t_top[c] > h_max or t_top[c] >= best[j, c]:
                continue
            dxj = ux[j]
            dyj = uy[j]
            sc = 1 if dxj > 0 else -1
            sr = 1 if dyj > 0 else -1
            tdc = tdcs[j]
            tdr = tdrs[j]
            hit = min(t_road[c], best[j, c])
            kind = 0
            t = t_top[c]
            if lo_ok <= t and hit <= hi_ok:  # the whole band is known to be road
                if hit < best[j, c]:
                    best[j, c] = hit
                    surf[j, c] = 0
                    idx[j, c] = -1
                continue
            while kerb > 0.0 and t < hit:
                u = (ox[j] + dxj * t - x0) * inv_res
                v = (oy[j] + dyj * t - y0) * inv_res
                col = int(math.floor(u))
                row = int(math.floor(v))
                if 0 <= row < hm and 0 <= col < wm:
                    d = np.int64(dist[row >> shift, col >> shift]) << shift
                    if d > 0:
                        reach = d * res - 1e-6
                        lo_ok = t - reach
                        hi_ok = t + reach
                        t += reach
                        continue
                    if raster[row, col] == raised:
                        hit = t  # the kerb top (t = t_top) or its vertical face
                        kind = 1
                        break
                # next to raised cells (or off the map): the exact cell walk from t
                tmc = t + (((col + 1 - u) if dxj > 0 else (u - col)) * tdc
                           if dxj != 0.0 else np.inf)
                tmr = t + (((row + 1 - v) if dyj > 0 else (v - row)) * tdr
                           if dyj != 0.0 else np.inf)
                while True:
                    if tmc < tmr:
                        t = tmc
                        tmc += tdc
                        col += sc
                    else:
                        t = tmr
                        tmr += tdr
                        row += sr
                    if t >= hit:
                        break
                    if 0 <= row < hm and 0 <= col < wm:
                        if raster[row, col] == raised:
                            hit = t  # a vertical kerb face
                            kind = 1
                            break
                        d = np.int64(dist[row >> shift, col >> shift]) << shift
                        if d > 1:
                            t += d * res - 1e-6  # from the entry point
                            break
            if hit < best[j, c]:
                best[j, c] = hit
                surf[j, c] = kind
                idx[j, c] = -1
