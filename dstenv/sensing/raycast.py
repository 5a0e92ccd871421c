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

A LIDAR whose beams repeat every sweep takes the fast path of
:mod:`dstenv.sensing.beampaths`: the same cells, written from traced beam paths.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dstenv.dst import SensorState
from dstenv.grid import GridSpec
from dstenv.sensing.beampaths import axis_start, paths_for

__all__ = ["sensor_grid"]


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
    p = paths_for(angles, spec, float(max_range), ox, oy)
    _cast(angles, ranges, hit, float(spec.cell_size), float(max_range), ox, oy, out,
          p.cos, p.sin, p.safe, p.start, p.cells, p.isteps, p.shared)
    return out


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
    """Cast all rays into ``out``; ``cos_a`` ... ``shared``: the tables of a
    :class:`~dstenv.sensing.beampaths.BeamPaths` (empty: walk every ray)."""
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
    tdu, tmu = axis_start(du, u0, ist)
    tdv, tmv = axis_start(dv, v0, jst)
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
