"""Ray casting of range measurements into an ego-centred sensor grid.

Every ray starts at the sensor (by default the ego, i.e. the centre of the ego cell
``spec.ego_cell``) and is walked through the grid cell by cell with the exact
Amanatides-Woo traversal in the continuous grid coordinates of :mod:`dstenv.grid`::

    u = i0 - x / c + 0.5        # floor(u) is the row    (GridSpec.to_cell)
    v = j0 - y / c + 0.5        # floor(v) is the column

so the cell of a ray's end point is exactly ``GridSpec.to_cell`` of that point, and the
cells in between are precisely the cells the segment crosses (4-connected; a segment
through a cell corner enters one of the two side cells).

Codes (:class:`dstenv.dst.SensorState`): 0 unknown, 1 free, 2 occupied, with precedence
occupied > free > unknown over all rays.

Beam paths (the fast path for a LIDAR whose beam directions repeat every sweep):
the second time the same angles, origin, grid and range come in, every beam's cells
up to the grid border are traced once (:class:`_Paths`) and each later ray writes the
prefix of its beam's path instead of walking. This is the walk's result exactly, not
an approximation: a ray's walk is decided by the comparisons ``tmu < tmv`` and by its
end cell. For a beam whose traced comparisons all keep a relative margin above
:func:`_margin_needed` (a bound on the rounding of both computations: the range enters
``du``, ``dv`` only through a few roundings), every ray of that beam makes the same
decisions; the prefix is used only when the path's counts of row and column steps
fit the ray's (``ni``, ``nj``), which puts the ray's end cell on the path. Beams
without that margin (rays through cell corners: the diagonals, the axes) and rays
that fail the count check are walked as before. Neighbouring beams share their first
cells; a ray skips the part of its path that the previous ray already marked.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dstenv.dst import SensorState
from dstenv.grid import GridSpec

__all__ = ["sensor_grid"]

_EPS = 2.0**-53  # unit roundoff of float64
_PATHS_KEPT = 8  # beam-path tables kept (one per LIDAR geometry in use)

_FREE = np.uint8(SensorState.FREE)
_OCC = np.uint8(SensorState.OCCUPIED)


def sensor_grid(
    angles: np.ndarray,
    ranges: np.ndarray,
    hit: np.ndarray,
    spec: GridSpec,
    max_range: float,
    origin: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Free / occupied / unknown grid from one ray per measurement.

    A ray of a hit (``hit[k]`` and ``ranges[k] <= max_range``) marks the cells it
    crosses before its end point free and the cell containing the end point occupied;
    cells behind stay unknown. A ray without hit (or a hit beyond ``max_range``)
    marks every cell up to ``min(ranges[k], max_range)``, the end cell included, free.
    A ray with a NaN range carries no measurement (a LIDAR dropout) and is skipped.
    Parts of rays outside the grid are ignored.

    Args:
        angles: ``(R,)`` float, ray directions in the ego frame [rad], 0 = +x
            (forward), counter-clockwise positive.
        ranges: ``(R,)`` float, distance from ``origin`` to the end point [m], >= 0
            or NaN.
        hit: ``(R,)`` bool, whether the ray ended on an obstacle.
        spec: the grid geometry (axis convention of :mod:`dstenv.grid`).
        max_range: the sensor's range [m]; rays are clipped to it.
        origin: ``(x, y)`` ego-frame position of the sensor [m]; must lie in the grid.

    Returns:
        ``(H, W) uint8`` codes of :class:`dstenv.dst.SensorState`.

    Raises:
        ValueError: mismatched shapes, negative ranges, ``max_range <= 0`` or an
            origin outside the grid.
    """
    angles = np.ascontiguousarray(angles, dtype=np.float64)
    ranges = np.ascontiguousarray(ranges, dtype=np.float64)
    hit = np.ascontiguousarray(hit, dtype=np.bool_)
    if angles.ndim != 1 or ranges.shape != angles.shape or hit.shape != angles.shape:
        raise ValueError(
            "sensor_grid: angles, ranges and hit must be 1-D of equal length, got shapes "
            f"{angles.shape}, {ranges.shape}, {hit.shape}"
        )
    if not max_range > 0:
        raise ValueError(f"sensor_grid: max_range must be > 0 m, got {max_range}")
    bad = _check_rays(angles, ranges)
    if bad == 1:
        raise ValueError(f"sensor_grid: ranges must be >= 0 m, got min {np.nanmin(ranges)}")
    if bad == 2:
        raise ValueError("sensor_grid: angles must be finite")
    ox, oy = float(origin[0]), float(origin[1])
    i0, j0 = spec.ego_cell
    # the origin's cell, as GridSpec.to_cell computes it
    if not (0 <= math.floor(i0 - ox / spec.cell_size + 0.5) < spec.height
            and 0 <= math.floor(j0 - oy / spec.cell_size + 0.5) < spec.width):
        raise ValueError(f"sensor_grid: origin {origin} lies outside the grid {spec.shape}")
    out = np.zeros(spec.shape, dtype=np.uint8)
    p = _paths(angles, spec, float(max_range), ox, oy)
    _cast(angles, ranges, hit, float(spec.cell_size), float(max_range), ox, oy, out,
          p.cos, p.sin, p.safe, p.start, p.cells, p.isteps, p.shared)
    return out


class _Paths:
    """Every beam's cells from the sensor to the grid border (see the module docstring).

    Attributes:
        cos, sin: ``(R,) float64`` ``math.cos`` / ``math.sin`` of the beam angles (the
            very values the walk computes).
        safe: ``(R,) bool`` the beam's comparisons keep the margin; its path is used.
        start: ``(R + 1,) int64`` beam ``k`` owns ``cells[start[k]:start[k + 1]]`` (its
            cells until it leaves the grid, flat indices) and
            ``isteps[start[k] + k:start[k + 1] + k + 1]`` (row steps among its first
            ``m`` steps, ``m = 0 ..`` the step that leaves the grid).
    """

    def __init__(self, angles: np.ndarray, spec: GridSpec, max_range: float, ox: float,
                 oy: float) -> None:
        n = angles.shape[0]
        h, w, c = spec.height, spec.width, float(spec.cell_size)
        self.angles = angles.copy()
        self.cos = np.empty(n)
        self.sin = np.empty(n)
        margin = np.empty(n)
        self.start = np.zeros(n + 1, np.int64)
        # beyond the grid from any origin inside it, and at least every ray's length
        far = max((h + w + 2) * c + abs(ox) + abs(oy), max_range)
        dtype = np.uint16 if h * w <= 1 << 16 else np.int32
        empty = np.zeros(0, dtype)
        _trace(angles, c, far, ox, oy, h, w, self.cos, self.sin, margin, self.start, empty,
               np.zeros(0, np.int32), False)
        self.cells = np.empty(self.start[-1], dtype)
        self.isteps = np.empty(self.start[-1] + n, np.int32)
        _trace(angles, c, far, ox, oy, h, w, self.cos, self.sin, margin, self.start,
               self.cells, self.isteps, True)
        self.safe = margin > _margin_needed(spec, far, ox, oy)
        self.shared = np.zeros(n, np.int64)
        _shared_prefix(self.start, self.cells, self.shared)


class _NoPaths:
    """Empty tables: every ray is walked."""

    cos = sin = np.zeros(0)
    safe = np.zeros(0, np.bool_)
    start = np.zeros(0, np.int64)
    cells = np.zeros(0, np.uint16)
    isteps = np.zeros(0, np.int32)
    shared = np.zeros(0, np.int64)


_paths_cache: dict[tuple, _Paths] = {}
_paths_seen: dict[tuple, None] = {}


def _paths(angles: np.ndarray, spec: GridSpec, max_range: float, ox: float,
           oy: float) -> _Paths | type[_NoPaths]:
    """The beam paths of this geometry, traced the second time it is seen."""
    n = angles.shape[0]
    if n == 0:
        return _NoPaths
    key = (n, float(angles[0]), float(angles[-1]), float(angles[n // 2]), spec.height,
           spec.width, spec.cell_size, max_range, ox, oy)
    p = _paths_cache.get(key)
    if p is not None and p.angles.tobytes() == angles.tobytes():
        return p
    if key not in _paths_seen:  # one-off angles (KITTI points, tests): just walk
        if len(_paths_seen) >= 4 * _PATHS_KEPT:
            _paths_seen.pop(next(iter(_paths_seen)))
        _paths_seen[key] = None
        return _NoPaths
    if len(_paths_cache) >= _PATHS_KEPT:
        _paths_cache.pop(next(iter(_paths_cache)))
    p = _paths_cache[key] = _Paths(angles, spec, max_range, ox, oy)
    return p


def _margin_needed(spec: GridSpec, far: float, ox: float, oy: float) -> float:
    """Relative margin between ``tmu`` and ``tmv`` above which a path's comparisons
    hold for every range up to ``far`` [m], with a safety factor of 64.

    ``tmu`` after ``n`` row steps is ``(fu + n) / |du|`` to ``(n + 2)`` roundings;
    ``du`` is the exact ``-r cos(a) / c`` to an absolute error ``err`` (a few roundings
    of numbers up to ``h + w + (|o| + far) / c``). A comparison is only made while the
    ray still has row and column steps left, so ``|du| >= gu`` (distance from the
    start to the first row boundary) and ``|dv| >= gv``. 0 margin: no path is safe.
    """
    c = float(spec.cell_size)
    i0, j0 = spec.ego_cell
    u0 = i0 - ox / c + 0.5
    v0 = j0 - oy / c + 0.5
    gu = min(u0 - math.floor(u0), math.floor(u0) + 1 - u0)
    gv = min(v0 - math.floor(v0), math.floor(v0) + 1 - v0)
    if min(gu, gv) < 1e-6:
        return math.inf
    err = 8 * _EPS * (spec.height + spec.width + 4 + (abs(ox) + abs(oy) + far) / c)
    return 64 * ((spec.height + spec.width + 8) * _EPS + err / gu + err / gv)


@numba.njit(cache=True)
def _check_rays(angles, ranges):  # pragma: no cover - numba
    """0: fine; 1: a negative range; 2: an angle that is not finite."""
    for k in range(angles.shape[0]):
        if ranges[k] < 0:
            return 1
        if not math.isfinite(angles[k]):
            return 2
    return 0


@numba.njit(cache=True)
def _cast(angles, ranges, hit, c, max_range, ox, oy, out, cos_a, sin_a, safe, start, cells,
          isteps, shared):  # pragma: no cover - numba
    h, w = out.shape
    flat = out.reshape(h * w)
    i0 = h // 2
    j0 = w // 2
    u0 = i0 - ox / c + 0.5
    v0 = j0 - oy / c + 0.5
    ist = int(math.floor(u0))
    jst = int(math.floor(v0))
    n = angles.shape[0]
    paths = start.shape[0] > 0
    ends = np.empty(n, np.int64)  # flat index of each occupied end cell, -1: none
    done = 0  # cells of the previous beam's path already marked free (0: walked / none)
    # pass 1: free cells (plain stores); pass 2: occupied end cells, which win.
    for k in range(n):
        ends[k] = -1
        r = ranges[k]
        prev = done
        done = 0
        if r != r:
            continue
        occ = hit[k] and r <= max_range
        rr = min(r, max_range)
        if paths:
            x = ox + rr * cos_a[k]
            y = oy + rr * sin_a[k]
        else:
            x = ox + rr * math.cos(angles[k])
            y = oy + rr * math.sin(angles[k])
        ue = i0 - x / c + 0.5
        ve = j0 - y / c + 0.5
        ie = int(math.floor(ue))
        je = int(math.floor(ve))
        if occ and 0 <= ie < h and 0 <= je < w:
            ends[k] = ie * w + je
        if paths and safe[k]:
            ni = abs(ie - ist)
            nj = abs(je - jst)
            s0 = start[k]
            exit_at = start[k + 1] - s0  # the step that leaves the grid
            m = min(ni + nj, exit_at)
            a = isteps[s0 + k + m]
            if a <= ni and m - a <= nj:  # the ray's walk is this prefix of the path
                # the part shared with the previous beam's path is already free
                skip = min(shared[k], prev, m)
                path = cells[s0 + skip:s0 + m]  # a slice: no wraparound code in the loop
                for q in range(m - skip):
                    flat[path[q]] = _FREE
                done = m
                if m < exit_at and not occ:
                    flat[cells[s0 + m]] = _FREE
                    done = m + 1
                continue
        _walk(flat, h, w, ist, jst, u0, v0, ue, ve, ie, je, occ)
    for k in range(n):
        if ends[k] >= 0:
            flat[ends[k]] = _OCC


@numba.njit(cache=True)
def _shared_prefix(start, cells, shared):  # pragma: no cover - numba
    for k in range(1, start.shape[0] - 1):
        a, b = start[k - 1], start[k]
        m = min(start[k] - a, start[k + 1] - b)
        q = 0
        while q < m and cells[a + q] == cells[b + q]:
            q += 1
        shared[k] = q


@numba.njit(cache=True)
def _trace(angles, c, far, ox, oy, h, w, cos_a, sin_a, margin, start, cells, isteps,
           fill):  # pragma: no cover - numba
    """Each beam's cells until it leaves the grid (a ray of length ``far``, compared
    crossings only); ``fill=False`` only counts them into ``start``."""
    i0 = h // 2
    j0 = w // 2
    u0 = i0 - ox / c + 0.5
    v0 = j0 - oy / c + 0.5
    ist = int(math.floor(u0))
    jst = int(math.floor(v0))
    for k in range(angles.shape[0]):
        ca = math.cos(angles[k])
        sa = math.sin(angles[k])
        cos_a[k] = ca
        sin_a[k] = sa
        du = (i0 - (ox + far * ca) / c + 0.5) - u0
        dv = (j0 - (oy + far * sa) / c + 0.5) - v0
        si = 1 if du > 0 else -1
        sj = 1 if dv > 0 else -1
        if du != 0.0:
            tdu = 1.0 / abs(du)
            tmu = ((ist + 1 - u0) if du > 0 else (u0 - ist)) * tdu
        else:
            tdu = np.inf
            tmu = np.inf
        if dv != 0.0:
            tdv = 1.0 / abs(dv)
            tmv = ((jst + 1 - v0) if dv > 0 else (v0 - jst)) * tdv
        else:
            tdv = np.inf
            tmv = np.inf
        i = ist
        j = jst
        m = 0
        a = 0
        s0 = start[k]
        low = np.inf
        while True:
            if fill:
                cells[s0 + m] = i * w + j
                isteps[s0 + k + m] = a
            if tmu < np.inf and tmv < np.inf:
                low = min(low, abs(tmu - tmv) / max(tmu, tmv))
            m += 1
            if tmu < tmv:
                i += si
                a += 1
                tmu += tdu
                if i < 0 or i >= h:
                    break
            else:
                j += sj
                tmv += tdv
                if j < 0 or j >= w:
                    break
        if fill:
            isteps[s0 + k + m] = a
        else:
            start[k + 1] = s0 + m
        margin[k] = low


@numba.njit(cache=True, inline="always")
def _walk(flat, h, w, ist, jst, u0, v0, ue, ve, ie, je, occ):  # pragma: no cover - numba
    """Mark free the cells of one ray from ``(ist, jst)`` to the end cell ``(ie, je)``.

    The exact traversal: ``|ie - ist|`` row steps and ``|je - jst|`` column steps in
    the order of the crossings (``tmu`` / ``tmv``: segment parameter of the next row /
    column boundary). Phase A compares crossings while both axes have steps left;
    phase B finishes the one axis left. A step that leaves the grid ends the ray
    (``ei`` / ``ej``: row / column steps until that happens), so no step needs a
    bounds check. The end cell itself is free unless the ray is a hit.
    """
    du = ue - u0
    dv = ve - v0
    ni = abs(ie - ist)
    nj = abs(je - jst)
    if du > 0:
        di, ei = w, h - ist
    else:
        di, ei = -w, ist + 1
    if dv > 0:
        dj, ej = 1, w - jst
    else:
        dj, ej = -1, jst + 1
    if du != 0.0:
        tdu = 1.0 / abs(du)
        tmu = ((ist + 1 - u0) if du > 0 else (u0 - ist)) * tdu
    else:
        tdu = np.inf
        tmu = np.inf
    if dv != 0.0:
        tdv = 1.0 / abs(dv)
        tmv = ((jst + 1 - v0) if dv > 0 else (v0 - jst)) * tdv
    else:
        tdv = np.inf
        tmv = np.inf
    ai = min(ni, ei)  # row steps left before the end row or the grid border
    aj = min(nj, ej)
    idx = ist * w + jst
    while ai > 0 and aj > 0:
        flat[idx] = _FREE
        if tmu < tmv:
            idx += di
            ai -= 1
            tmu += tdu
        else:
            idx += dj
            aj -= 1
            tmv += tdv
    if (ai == 0 and ei <= ni) or (aj == 0 and ej <= nj):
        return  # the last step left the grid
    if ai > 0:
        for _ in range(ai):
            flat[idx] = _FREE
            idx += di
        if ei <= ni:
            return
    else:
        for _ in range(aj):
            flat[idx] = _FREE
            idx += dj
        if ej <= nj:
            return
    if not occ:
        flat[idx] = _FREE
