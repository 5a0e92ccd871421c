"""Beam paths: the sensor grid's fast path for a LIDAR whose beam directions repeat.

The second time :func:`dstenv.sensing.raycast.sensor_grid` gets the same angles,
origin, grid and range, every beam's cells up to the grid border are traced once
(:class:`BeamPaths`), and each later ray marks a prefix of its beam's path instead of
walking the grid. This is the walk's result exactly, not an approximation: a ray's
walk is decided by the comparisons ``tmu < tmv`` and by its end cell. For a beam
whose traced comparisons all keep a relative margin above :func:`_margin_needed` (a
bound on the rounding of both computations: the range enters ``du``, ``dv`` only
through a few roundings), every ray of that beam makes the same decisions; the
prefix is used only when the path's counts of row and column steps fit the ray's
(``ni``, ``nj``), which puts the ray's end cell on the path. Beams without that margin
(rays through cell corners: the diagonals, the axes) and rays that fail the count
check are walked as before. Neighbouring beams share their first cells; a ray skips
the part of its path that the previous ray already marked.

One-off angle sets (a point cloud's own rays, tests) are never traced: a geometry
is traced when it comes back, and the last :data:`_PATHS_KEPT` are kept.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dstenv.grid import GridSpec

__all__ = ["BeamPaths", "NO_PATHS", "paths_for"]

_EPS = 2.0**-53  # unit roundoff of float64
_PATHS_KEPT = 8  # beam-path tables kept (one per LIDAR geometry in use)


class BeamPaths:
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
        """Trace the beams ``angles`` [rad] from the sensor at ``(ox, oy)`` [m] (ego
        frame) through ``spec``'s grid; ``max_range`` [m] bounds the rays to come."""
        n = angles.shape[0]
        h, w, c = spec.height, spec.width, float(spec.cell_size)
        self.angles = angles.copy()
        self.cos = np.empty(n)
        self.sin = np.empty(n)
        margin = np.empty(n)
        self.start = np.zeros(n + 1, np.int64)
        # beyond the grid from any origin inside it, and at least every ray's length
        far = max((h + w + 2) * c + abs(ox) + abs(oy), max_range)
        dtype = np.uint16 if h * w <= 1 << 16 else np.int32  # flat cell indices
        steps = np.uint16 if h < 1 << 16 else np.int32  # row steps, at most h
        _trace(angles, c, far, ox, oy, h, w, self.cos, self.sin, margin, self.start,
               np.zeros(0, dtype), np.zeros(0, steps), False)
        self.cells = np.empty(self.start[-1], dtype)
        self.isteps = np.empty(self.start[-1] + n, steps)
        _trace(angles, c, far, ox, oy, h, w, self.cos, self.sin, margin, self.start,
               self.cells, self.isteps, True)
        self.safe = margin > _margin_needed(spec, far, ox, oy)
        self.shared = np.zeros(n, np.int64)
        _shared_prefix(self.start, self.cells, self.shared)


    @classmethod
    def none(cls) -> "BeamPaths":
        """Empty tables: every ray is walked."""
        p = cls.__new__(cls)
        p.angles = p.cos = p.sin = np.zeros(0)
        p.safe = np.zeros(0, np.bool_)
        p.start = p.shared = np.zeros(0, np.int64)
        p.cells = np.zeros(0, np.uint16)
        p.isteps = np.zeros(0, np.uint16)
        return p


#: no tables (the kernel walks every ray)
NO_PATHS = BeamPaths.none()


_paths_cache: dict[tuple, BeamPaths] = {}
_paths_seen: dict[tuple, None] = {}


def paths_for(angles: np.ndarray, spec: GridSpec, max_range: float, ox: float,
              oy: float) -> BeamPaths:
    """The beam paths of this geometry, traced the second time it is seen.

    Args:
        angles: ``(R,) float64`` finite ray directions [rad] (ego frame).
        spec: the grid; max_range: the sensor's range [m]; ox, oy: the sensor
            position in the ego frame [m], inside the grid.

    Returns:
        The traced :class:`BeamPaths`, or :data:`NO_PATHS` (first sight, no rays).
    """
    n = angles.shape[0]
    if n == 0:
        return NO_PATHS
    key = (n, float(angles[0]), float(angles[-1]), float(angles[n // 2]), spec.height,
           spec.width, spec.cell_size, max_range, ox, oy)
    p = _paths_cache.get(key)
    if p is not None and p.angles.tobytes() == angles.tobytes():
        return p
    if key not in _paths_seen:  # one-off angles (KITTI points, tests): just walk
        if len(_paths_seen) >= 4 * _PATHS_KEPT:
            _paths_seen.pop(next(iter(_paths_seen)))
        _paths_seen[key] = None
        return NO_PATHS
    if len(_paths_cache) >= _PATHS_KEPT:
        _paths_cache.pop(next(iter(_paths_cache)))
    p = _paths_cache[key] = BeamPaths(angles, spec, max_range, ox, oy)
    return p


def _margin_needed(spec: GridSpec, far: float, ox: float, oy: float) -> float:
    """Relative margin between ``tmu`` and ``tmv`` above which a path's comparisons
    hold for every range up to ``far`` [m], with a safety factor of 64.

    ``tmu`` after ``n`` row steps is ``(fu + n) / |du|`` to ``(n + 2)`` roundings;
    ``du`` is the exact ``-r cos(a) / c`` to an absolute error ``err`` (a few roundings
    of numbers up to ``h + w + (|o| + far) / c``). A comparison is only made while the
    ray still has row and column steps left, so ``|du| >= gu`` (distance from the
    start to the first row boundary) and ``|dv| >= gv``. A start within 1e-6 of a
    cell border gives ``inf``: no path is used.
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


@numba.njit(cache=True, inline="always")
def axis_start(d: float, p0: float, cell: int) -> tuple[float, float]:  # pragma: no cover
    """Amanatides-Woo set-up along one grid axis for a ray that moves ``d`` cells per
    unit of its parameter t from coordinate ``p0`` inside cell ``cell``: ``(t per
    cell, t to the first cell border)``, both ``inf`` when the ray does not move
    along this axis."""
    if d != 0.0:
        td = 1.0 / abs(d)
        return td, ((cell + 1 - p0) if d > 0 else (p0 - cell)) * td
    return np.inf, np.inf


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
        tdu, tmu = axis_start(du, u0, ist)
        tdv, tmv = axis_start(dv, v0, jst)
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
