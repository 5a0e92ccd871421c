"""The polyline kernels of :mod:`dstenv.sim.lanegeom` against the plain numpy
expressions they replace: bit-identical (a seed must give the same lanes), plus the
geometric facts each must hold."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sim.lanegeom import bezier, cut_polyline, fillet_curve, offset_polyline


# ----------------------------------------------------------------- numpy references
def ref_cut(poly, s0, s1):
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poly, axis=0).T))])
    inner = poly[(cum > s0) & (cum < s1)]
    a = [np.interp(s0, cum, poly[:, 0]), np.interp(s0, cum, poly[:, 1])]
    b = [np.interp(s1, cum, poly[:, 0]), np.interp(s1, cum, poly[:, 1])]
    return np.vstack([a, inner, b])


def ref_offset(poly, d):
    t = np.diff(poly, axis=0)
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    n_seg = np.stack([-t[:, 1], t[:, 0]], -1)
    n_pt = np.vstack([n_seg[:1], n_seg[:-1] + n_seg[1:], n_seg[-1:]])
    n_pt /= np.maximum(np.hypot(n_pt[:, 0], n_pt[:, 1]), 1e-12)[:, None]
    cosh = np.ones(len(poly))
    cosh[1:-1] = np.clip(np.einsum("ij,ij->i", n_pt[1:-1], n_seg[1:]), 0.5, 1.0)
    return poly + n_pt * (d / cosh)[:, None]


def ref_bezier(p0, h0, p1, h1, n=24, k=0.42):
    d = k * np.hypot(*(p1 - p0))
    c0 = p0 + d * np.array([np.cos(h0), np.sin(h0)])
    c1 = p1 - d * np.array([np.cos(h1), np.sin(h1)])
    t = np.linspace(0, 1, n)[:, None]
    b0, b1, b2, b3 = (1 - t) ** 3, 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t ** 2, t ** 3
    return b0 * p0 + b1 * c0 + b2 * c1 + b3 * p1


def ref_fillet(p0, h0, p1, h1, r):
    d0, d1 = np.array([np.cos(h0), np.sin(h0)]), np.array([np.cos(h1), np.sin(h1)])
    cross = d0[0] * d1[1] - d0[1] * d1[0]
    if abs(cross) < 1e-3:
        return None
    t0 = ((p1 - p0)[0] * d1[1] - (p1 - p0)[1] * d1[0]) / cross
    corner = p0 + t0 * d0
    theta = float(np.angle(np.exp(1j * (h1 - h0))))
    tl = r * np.tan(abs(theta) / 2)
    a, b = corner - tl * d0, corner + tl * d1
    if (a - p0) @ d0 < 0 or (p1 - b) @ d1 < 0:
        return None
    centre = a + np.sign(theta) * r * np.array([-d0[1], d0[0]])
    ang0 = np.arctan2(*(a - centre)[::-1])
    arc = ang0 + np.linspace(0, theta, max(int(abs(theta) * r / 0.4), 4))
    pts = centre + r * np.stack([np.cos(arc), np.sin(arc)], -1)
    return np.vstack([p0, pts, p1])


def _polys(rng, n=300):
    for _ in range(n):
        k = int(rng.integers(2, 12))
        steps = rng.normal(size=(k - 1, 2)) * rng.uniform(0.1, 40.0)
        yield np.vstack([[0.0, 0.0], np.cumsum(steps, 0)]) + rng.uniform(-500, 500, 2)


# ----------------------------------------------------------------- equivalence
def test_cut_polyline_matches_numpy_bit_for_bit():
    rng = np.random.default_rng(0)
    for poly in _polys(rng):
        total = float(np.hypot(*np.diff(poly, axis=0).T).sum())
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poly, axis=0).T))])
        for s0, s1 in [rng.uniform(0, total, 2), (0.0, total), (-1.0, total + 1.0),
                       (cum[min(1, len(cum) - 1)], cum[-1])]:
            s0, s1 = float(min(s0, s1)), float(max(s0, s1))
            np.testing.assert_array_equal(cut_polyline(poly, s0, s1), ref_cut(poly, s0, s1))


def test_offset_polyline_matches_numpy_bit_for_bit():
    rng = np.random.default_rng(1)
    for poly in _polys(rng):
        d = float(rng.uniform(-8, 8))
        np.testing.assert_array_equal(offset_polyline(poly, d), ref_offset(poly.copy(), d))
    # a reversed view (the backward lanes of a street) and a 2-point line
    poly = next(_polys(rng))
    np.testing.assert_array_equal(offset_polyline(poly[::-1], -1.6),
                                  ref_offset(poly[::-1].copy(), -1.6))
    two = np.array([[0.0, 0.0], [10.0, 0.0]])
    np.testing.assert_array_equal(offset_polyline(two, 2.0), [[0.0, 2.0], [10.0, 2.0]])


def test_bezier_matches_numpy_bit_for_bit():
    rng = np.random.default_rng(2)
    for _ in range(300):
        p0, p1 = rng.uniform(-300, 300, 2), rng.uniform(-300, 300, 2)
        h0, h1 = (float(h) for h in rng.uniform(-4, 4, 2))
        n, k = int(rng.choice([16, 24])), float(rng.choice([0.4, 0.42]))
        out = bezier(p0, h0, p1, h1, n=n, k=k)
        np.testing.assert_array_equal(out, ref_bezier(p0, h0, p1, h1, n, k))
        np.testing.assert_array_equal(out[[0, -1]], [p0, p1])  # passes through its ends


@pytest.mark.parametrize("seed", [3, 4])
def test_fillet_curve_matches_numpy_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    made = 0
    for _ in range(400):
        p0 = rng.uniform(-50, 50, 2)
        h0 = float(rng.uniform(-np.pi, np.pi))
        h1 = h0 + float(rng.choice([-1, 1]) * rng.uniform(0.2, 2.5))
        p1 = p0 + rng.uniform(5, 40) * np.array([np.cos(h0), np.sin(h0)]) \
            + rng.uniform(5, 40) * np.array([np.cos(h1), np.sin(h1)]) + rng.normal(size=2)
        r = float(rng.uniform(3, 12))
        out, ref = fillet_curve(p0, h0, p1, h1, r), ref_fillet(p0, h0, p1, h1, r)
        assert (out is None) == (ref is None)
        if ref is not None:
            made += 1
            np.testing.assert_array_equal(out, ref)
            # the arc is a circle of radius r: circumradius of its first, middle, last point
            a, b, c = out[1], out[len(out) // 2], out[-2]
            ab, bc, ca = np.hypot(*(b - a)), np.hypot(*(c - b)), np.hypot(*(a - c))
            area = abs((b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0]) / 2
            if area > 1e-3:
                assert ab * bc * ca / (4 * area) == pytest.approx(r, rel=1e-6)
    assert made > 100  # the cases above mostly have room for the arc
    # parallel lines: no corner, no fillet
    assert fillet_curve(np.zeros(2), 0.0, np.array([10.0, 3.0]), 0.0, 5.0) is None
