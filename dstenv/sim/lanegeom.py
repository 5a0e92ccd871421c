"""Polyline geometry of lanes: resampling, cutting, offsetting, turn curves.

A city has thousands of lanes, each built from a few of these calls, so each is one
small numba kernel instead of a dozen numpy calls on arrays of ~10 points. The
kernels do the same floating-point operations in the same order as the plain numpy
expressions in their docstrings (``tests/sim/test_lanegeom.py`` keeps those as
references and demands bit-identical results): a seed gives the same lanes as before.
"""

from __future__ import annotations

import functools

import numba as nb
import numpy as np

__all__ = ["SPACING", "resample", "resample_each", "resample_many", "cut_polyline",
           "offset_polyline", "bezier", "fillet_curve", "interp_row"]

SPACING = 0.5  # [m] largest distance between resampled lane points


def resample(poly: np.ndarray, spacing: float = SPACING) -> np.ndarray:
    """Evenly spaced points along a polyline: ``(K, 2) -> (M, 2) float64``, same ends."""
    out = _resample_distinct(np.ascontiguousarray(poly, np.float64), float(spacing))
    if not len(out):
        raise ValueError("lane polyline needs two distinct points")
    return out


@nb.njit(cache=True)
def _resample_distinct(poly, spacing):  # pragma: no cover - numba
    """:func:`_resample` of the :func:`_distinct` points; empty when fewer than two."""
    poly = _distinct(poly)
    if poly.shape[0] < 2:
        return np.empty((0, 2))
    return _resample(poly, spacing)


@nb.njit(cache=True)
def _distinct(poly):  # pragma: no cover - numba
    """The points of ``poly (K, 2)`` more than 1e-9 m from their predecessor in
    ``poly`` (the first is always kept)."""
    keep = np.ones(poly.shape[0], np.bool_)
    for i in range(1, poly.shape[0]):
        keep[i] = np.hypot(poly[i, 0] - poly[i - 1, 0], poly[i, 1] - poly[i - 1, 1]) > 1e-9
    return poly[keep]


@nb.njit(cache=True)
def _resample(poly, spacing):  # pragma: no cover - numba
    """:func:`resample` of a polyline without repeated points (one pass, no temporaries
    beyond the output: generating a city resamples thousands of lanes)."""
    k = poly.shape[0]
    cum = np.empty(k)
    cum[0] = 0.0
    for i in range(1, k):
        cum[i] = cum[i - 1] + np.hypot(poly[i, 0] - poly[i - 1, 0], poly[i, 1] - poly[i - 1, 1])
    n = max(int(np.ceil(cum[-1] / spacing)), 1) + 1
    out = np.empty((n, 2))
    step = cum[-1] / (n - 1)
    j = 0
    for m in range(n):
        t = m * step if m < n - 1 else cum[-1]
        while j < k - 2 and cum[j + 1] < t:
            j += 1
        d = cum[j + 1] - cum[j]
        f = (t - cum[j]) / d if d > 0 else 0.0
        f = min(max(f, 0.0), 1.0)
        out[m, 0] = poly[j, 0] + f * (poly[j + 1, 0] - poly[j, 0])
        out[m, 1] = poly[j, 1] + f * (poly[j + 1, 1] - poly[j, 1])
    return out


def resample_many(pts: np.ndarray, ptr: np.ndarray, spacing: float = SPACING
                  ) -> list[np.ndarray]:
    """:func:`resample` of many polylines without repeated points at once: the lines
    ``pts[ptr[i]:ptr[i + 1]]`` (``pts (P, 2) float64``, ``ptr (L + 1,) int64``) ->
    ``L`` arrays ``(M_i, 2) float64`` (views of one array)."""
    out, optr = _resample_many(np.ascontiguousarray(pts, np.float64),
                               np.asarray(ptr, np.int64), float(spacing))
    bounds = optr.tolist()
    return [out[bounds[i]:bounds[i + 1]] for i in range(len(bounds) - 1)]


@nb.njit(cache=True)
def _resample_many(pts, ptr, spacing):  # pragma: no cover - numba
    n_l = ptr.shape[0] - 1
    optr = np.zeros(n_l + 1, np.int64)
    for i in range(n_l):  # the point counts, with :func:`_resample`'s arithmetic
        total = 0.0
        for j in range(ptr[i] + 1, ptr[i + 1]):
            total = total + np.hypot(pts[j, 0] - pts[j - 1, 0], pts[j, 1] - pts[j - 1, 1])
        optr[i + 1] = optr[i] + max(int(np.ceil(total / spacing)), 1) + 1
    out = np.empty((optr[n_l], 2))
    for i in range(n_l):
        out[optr[i]:optr[i + 1]] = _resample(pts[ptr[i]:ptr[i + 1]], spacing)
    return out, optr


def resample_each(pts: np.ndarray, ptr: np.ndarray, spacing: float = SPACING
                  ) -> tuple[list[np.ndarray], int]:
    """:func:`resample` of each line ``pts[ptr[i]:ptr[i + 1]]`` (``pts (P, 2) float64``,
    ``ptr (L + 1,) int64``), repeated points allowed: ``(L arrays (M_i, 2) float64,
    views of one array; the first line without two distinct points or -1)``."""
    out, optr, bad = _resample_each(np.ascontiguousarray(pts, np.float64),
                                    np.asarray(ptr, np.int64), float(spacing))
    bounds = optr.tolist()
    return [out[bounds[i]:bounds[i + 1]] for i in range(len(bounds) - 1)], int(bad)


@nb.njit(cache=True)
def _resample_each(pts, ptr, spacing):  # pragma: no cover - numba
    n_l = ptr.shape[0] - 1
    parts = []
    optr = np.zeros(n_l + 1, np.int64)
    bad = -1
    for i in range(n_l):
        r = _resample_distinct(pts[ptr[i]:ptr[i + 1]], spacing)
        if r.shape[0] == 0 and bad < 0:
            bad = i
        parts.append(r)
        optr[i + 1] = optr[i] + r.shape[0]
    out = np.empty((optr[n_l], 2))
    for i in range(n_l):
        out[optr[i]:optr[i + 1]] = parts[i]
    return out, optr, bad


def cut_polyline(poly: np.ndarray, s0: float, s1: float) -> np.ndarray:
    """The piece of a polyline ``(K, 2)`` between arc lengths ``s0 < s1`` [m]:
    ``(M, 2) float64``, the points strictly inside and the two interpolated ends
    (``np.interp`` of the cumulative arc length, to the bit)."""
    return _cut(np.ascontiguousarray(poly, np.float64), float(s0), float(s1))


@nb.njit(cache=True)
def interp_row(s, cum, poly, out, row):  # pragma: no cover - numba
    """``out[row] = np.interp(s, cum, poly[:, c])`` for both columns ``c``, as numpy
    computes it (``cum (K,)`` increasing arc lengths of the points ``poly (K, 2)``)."""
    k = cum.shape[0]
    for c in range(2):
        if s < cum[0]:
            out[row, c] = poly[0, c]
        elif s >= cum[k - 1]:
            out[row, c] = poly[k - 1, c]
        else:
            j = 0
            while cum[j + 1] <= s:  # the last j with cum[j] <= s
                j += 1
            if cum[j] == s:
                out[row, c] = poly[j, c]
            else:
                slope = (poly[j + 1, c] - poly[j, c]) / (cum[j + 1] - cum[j])
                v = slope * (s - cum[j]) + poly[j, c]
                if np.isnan(v):
                    v = slope * (s - cum[j + 1]) + poly[j + 1, c]
                    if np.isnan(v) and poly[j, c] == poly[j + 1, c]:
                        v = poly[j, c]
                out[row, c] = v


@nb.njit(cache=True)
def _cut(poly, s0, s1):  # pragma: no cover - numba
    k = poly.shape[0]
    cum = np.empty(k)
    cum[0] = 0.0
    for i in range(1, k):
        cum[i] = cum[i - 1] + np.hypot(poly[i, 0] - poly[i - 1, 0], poly[i, 1] - poly[i - 1, 1])
    inner = 0
    for i in range(k):
        inner += s0 < cum[i] < s1
    out = np.empty((inner + 2, 2))
    interp_row(s0, cum, poly, out, 0)
    m = 1
    for i in range(k):
        if s0 < cum[i] < s1:
            out[m, 0], out[m, 1] = poly[i, 0], poly[i, 1]
            m += 1
    interp_row(s1, cum, poly, out, m)
    return out


def offset_polyline(poly: np.ndarray, d: float) -> np.ndarray:
    """Polyline ``(K >= 2, 2)`` shifted by ``d`` [m] to its left (negative: right),
    mitred joints: ``(K, 2) float64``. Each point moves along the normalised sum of
    the unit normals of its two segments, by ``d / cos`` of the half joint angle
    (the cosine clipped to ``[0.5, 1]``)."""
    return _offset(np.ascontiguousarray(poly, np.float64), float(d))


@nb.njit(cache=True)
def _offset(poly, d):  # pragma: no cover - numba
    k = poly.shape[0]
    ns = np.empty((k - 1, 2))  # unit left normal of each segment
    for i in range(k - 1):
        tx, ty = poly[i + 1, 0] - poly[i, 0], poly[i + 1, 1] - poly[i, 1]
        nrm = max(np.hypot(tx, ty), 1e-12)
        ns[i, 0], ns[i, 1] = -(ty / nrm), tx / nrm
    out = np.empty((k, 2))
    for i in range(k):
        if i == 0:
            nx, ny = ns[0, 0], ns[0, 1]
        elif i == k - 1:
            nx, ny = ns[k - 2, 0], ns[k - 2, 1]
        else:
            nx, ny = ns[i - 1, 0] + ns[i, 0], ns[i - 1, 1] + ns[i, 1]
        nrm = max(np.hypot(nx, ny), 1e-12)
        nx, ny = nx / nrm, ny / nrm
        cosh = 1.0
        if 0 < i < k - 1:
            cosh = min(max(nx * ns[i, 0] + ny * ns[i, 1], 0.5), 1.0)
        f = d / cosh
        out[i, 0], out[i, 1] = poly[i, 0] + nx * f, poly[i, 1] + ny * f
    return out


def bezier(p0, h0: float, p1, h1: float, n: int = 24, k: float = 0.42) -> np.ndarray:
    """Cubic Bezier leaving ``p0`` at heading ``h0`` and reaching ``p1`` at ``h1``
    (control points ``k`` times the chord ahead of ``p0`` and behind ``p1``):
    ``(n, 2) float64``."""
    return _bezier(float(p0[0]), float(p0[1]), float(h0), float(p1[0]), float(p1[1]),
                   float(h1), _bernstein(n), float(k))


@functools.lru_cache(maxsize=8)
def _bernstein(n: int) -> np.ndarray:
    """``(4, n) float64`` cubic Bernstein weights at ``n`` even steps of ``[0, 1]``
    (read-only; numpy's powers, which differ from repeated products in the last bit)."""
    t = np.linspace(0, 1, n)
    out = np.stack(((1 - t) ** 3, 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t ** 2, t ** 3))
    out.flags.writeable = False
    return out


@nb.njit(cache=True)
def _bezier(x0, y0, h0, x1, y1, h1, b, k):  # pragma: no cover - numba
    d = k * np.hypot(x1 - x0, y1 - y0)
    cx0, cy0 = x0 + d * np.cos(h0), y0 + d * np.sin(h0)
    cx1, cy1 = x1 - d * np.cos(h1), y1 - d * np.sin(h1)
    out = np.empty((b.shape[1], 2))
    for i in range(b.shape[1]):
        out[i, 0] = b[0, i] * x0 + b[1, i] * cx0 + b[2, i] * cx1 + b[3, i] * x1
        out[i, 1] = b[0, i] * y0 + b[1, i] * cy0 + b[2, i] * cy1 + b[3, i] * y1
    return out


def fillet_curve(p0, h0: float, p1, h1: float, r: float) -> np.ndarray | None:
    """Straight - circular arc of radius ``r`` - straight from ``p0`` (heading ``h0``) to
    ``p1`` (heading ``h1``): ``(M, 2) float64``, the arc sampled every <= 0.4 m (at
    least 4 points); None when the two lines do not meet ahead with room for the arc."""
    out = _fillet(float(p0[0]), float(p0[1]), float(h0), float(p1[0]), float(p1[1]),
                  float(h1), float(r))
    return out if len(out) else None


@nb.njit(cache=True)
def _fillet(x0, y0, h0, x1, y1, h1, r):  # pragma: no cover - numba
    """:func:`fillet_curve`; an empty array stands for None."""
    none = np.empty((0, 2))
    d0x, d0y, d1x, d1y = np.cos(h0), np.sin(h0), np.cos(h1), np.sin(h1)
    cross = d0x * d1y - d0y * d1x
    if abs(cross) < 1e-3:
        return none
    t0 = ((x1 - x0) * d1y - (y1 - y0) * d1x) / cross
    cx, cy = x0 + t0 * d0x, y0 + t0 * d0y  # where the two lines meet
    dh = h1 - h0
    theta = np.arctan2(np.sin(dh), np.cos(dh))  # np.angle(np.exp(1j * dh))
    tl = r * np.tan(abs(theta) / 2)
    ax, ay = cx - tl * d0x, cy - tl * d0y
    bx, by = cx + tl * d1x, cy + tl * d1y
    if (ax - x0) * d0x + (ay - y0) * d0y < 0 or (x1 - bx) * d1x + (y1 - by) * d1y < 0:
        return none
    sr = np.sign(theta) * r  # +r: centre on the left
    ox, oy = ax + sr * -d0y, ay + sr * d0x
    ang0 = np.arctan2(ay - oy, ax - ox)
    n = max(int(abs(theta) * r / 0.4), 4)
    out = np.empty((n + 2, 2))
    out[0, 0], out[0, 1] = x0, y0
    step = theta / (n - 1)  # np.linspace(0, theta, n)
    for i in range(n):
        a = ang0 + (i * step if i < n - 1 else theta)
        out[i + 1, 0], out[i + 1, 1] = ox + r * np.cos(a), oy + r * np.sin(a)
    out[n + 1, 0], out[n + 1, 1] = x1, y1
    return out
