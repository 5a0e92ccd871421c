"""The polyline kernels of :mod:`dstenv.sim.lanegeom` against the plain numpy
expressions they replace: bit-identical (a seed must give the same lanes), plus the
geometric facts each must hold."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sim.lanegeom import bezier, cut_polyline, fillet_curve, offset_polyline

from .numerics import numpy_math_is_libm


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
            if numpy_math_is_libm():
                np.testing.assert_array_equal(out, ref)
            else:  # numpy's SIMD math (AVX-512): a few ulps of these ~50 m coordinates
                np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
            # the arc is a circle of radius r: circumradius of its first, middle, last point
            a, b, c = out[1], out[len(out) // 2], out[-2]
            ab, bc, ca = np.hypot(*(b - a)), np.hypot(*(c - b)), np.hypot(*(a - c))
            area = abs((b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0]) / 2
            if area > 1e-3:
                assert ab * bc * ca / (4 * area) == pytest.approx(r, rel=1e-6)
    assert made > 100  # the cases above mostly have room for the arc
    # parallel lines: no corner, no fillet
    assert fillet_curve(np.zeros(2), 0.0, np.array([10.0, 3.0]), 0.0, 5.0) is None


def test_lane_lengths_and_speed_limits_match_numpy():
    """``NetworkBuilder.build``'s per-lane kernel against the numpy loop it replaces
    (pairwise sums, ``np.angle(np.exp(1j * dh))``), on lanes of 2 to 700 points."""
    from dstenv.sim.lanes import LATERAL_ACCEL, LaneKind, NetworkBuilder, _pairwise_sum

    rng = np.random.default_rng(5)
    for n in [0, 1, 7, 8, 9, 64, 128, 129, 300, 1000]:
        a = rng.uniform(0.1, 0.5, n)
        assert _pairwise_sum(a, 0, n) == a.sum()
    builder = NetworkBuilder()
    for k in range(60):
        n = int(rng.integers(2, 700)) if k % 3 else int(rng.integers(2, 12))
        poly = np.cumsum(rng.normal(size=(n, 2)) + [0.4, 0.0], 0)
        builder.add(poly, LaneKind.CONNECTOR if k % 2 else LaneKind.ROAD)
    net = builder.build(np.zeros((0, 2)), np.zeros(0), np.zeros(0), 3.25)
    d_all = np.diff(net.pts, axis=0)
    h_all, seg_all = np.arctan2(d_all[:, 1], d_all[:, 0]), np.hypot(d_all[:, 0], d_all[:, 1])
    for i in range(len(net)):
        a, b = net.start[i], net.start[i] + net.npts[i] - 1
        length = float(seg_all[a:b].sum())
        vmax = 30.0
        h = h_all[a:b]
        if net.kind[i] == LaneKind.CONNECTOR and len(h) > 4:
            dh = np.abs(np.angle(np.exp(1j * (h[4:] - h[:-4]))))
            vmax = min(30.0, np.sqrt(LATERAL_ACCEL / max(dh.max() / (4 * length / len(h)), 1e-6)))
        assert net.length[i] == length and net.vmax[i] == vmax
    assert (net.vmax < 30.0).any()  # some connectors are curved enough to be limited


def test_sidewalk_split_matches_numpy():
    """The sidewalk ring split (``sidewalks._split``) against its numpy expression."""
    from dstenv.sim.sidewalks import _split, rounded_rect

    def ref_split(ring, cuts):
        cum = np.concatenate([[0], np.cumsum(np.hypot(*np.diff(ring, axis=0).T))])
        total, out = cum[-1], []
        for i, s0 in enumerate(cuts):
            s1 = cuts[(i + 1) % len(cuts)] + (total if i + 1 == len(cuts) else 0.0)
            s = np.concatenate([[s0], cum[(cum > s0) & (cum < s1)],
                                cum[cum < s1 - total] + total if s1 > total else [], [s1]])
            s = np.where(s > total, s - total, s)
            out.append(np.stack([np.interp(s, cum, ring[:, 0]),
                                 np.interp(s, cum, ring[:, 1])], -1))
        return out

    rng = np.random.default_rng(6)
    for _ in range(200):
        x0, y0 = rng.uniform(-300, 300, 2)
        ring = rounded_rect(x0, x0 + rng.uniform(5, 150), y0, y0 + rng.uniform(5, 150))
        total = float(np.hypot(*np.diff(ring, axis=0).T).sum())
        cuts = sorted(rng.uniform(0, total, int(rng.integers(1, 9))).tolist())
        got, ref = _split(ring, cuts), ref_split(ring, cuts)
        assert len(got) == len(ref) == len(cuts)
        for g, r in zip(got, ref):
            np.testing.assert_array_equal(g, r)
        # consecutive pieces meet: each ends where the next starts
        for i in range(len(got)):
            np.testing.assert_allclose(got[i][-1], got[(i + 1) % len(got)][0], atol=1e-9)


def test_rounded_rect_matches_numpy():
    from dstenv.sim.sidewalks import _QUARTER, rounded_rect

    def ref(x0, x1, y0, y1, r=1.0):
        r = min(r, (x1 - x0) / 3, (y1 - y0) / 3)
        pts = [np.stack([cx + r * np.cos(a0 + _QUARTER), cy + r * np.sin(a0 + _QUARTER)], -1)
               for cx, cy, a0 in ((x1 - r, y0 + r, -np.pi / 2), (x1 - r, y1 - r, 0.0),
                                  (x0 + r, y1 - r, np.pi / 2), (x0 + r, y0 + r, np.pi))]
        ring = np.concatenate(pts)
        return np.vstack([ring, ring[:1]])

    rng = np.random.default_rng(7)
    for _ in range(200):
        x0, y0 = rng.uniform(-300, 300, 2)
        box = (x0, x0 + rng.uniform(1, 150), y0, y0 + rng.uniform(1, 150))
        np.testing.assert_array_equal(rounded_rect(*box), ref(*box))
    ring = rounded_rect(0.0, 10.0, 0.0, 6.0)
    assert ring.shape == (21, 2) and (ring[0] == ring[-1]).all()
    assert ring[:, 0].min() == 0.0 and ring[:, 1].max() == 6.0  # touches the box


def test_resample_many_matches_one_by_one():
    from dstenv.sim.lanegeom import resample, resample_many

    rng = np.random.default_rng(8)
    polys = list(_polys(rng, 50))
    ptr = np.cumsum([0] + [len(p) for p in polys])
    many = resample_many(np.concatenate(polys), ptr)
    assert len(many) == len(polys)
    for got, poly in zip(many, polys):
        np.testing.assert_array_equal(got, resample(poly))
        assert np.hypot(*np.diff(got, axis=0).T).max() <= 0.5 + 1e-9


def test_resample_each_matches_one_by_one_with_repeated_points():
    # NetworkBuilder resamples its lanes in batches through resample_each (issue 16)
    from dstenv.sim.lanegeom import resample, resample_each
    from dstenv.sim.lanes import NetworkBuilder

    rng = np.random.default_rng(9)
    polys = [np.repeat(p, rng.integers(1, 3, len(p)), axis=0) for p in _polys(rng, 50)]
    ptr = np.cumsum([0] + [len(p) for p in polys])
    each, bad = resample_each(np.concatenate(polys), ptr)
    assert bad == -1 and len(each) == len(polys)
    for got, poly in zip(each, polys):
        np.testing.assert_array_equal(got, resample(poly))
    stuck = polys[:3] + [np.array([[1.0, 2.0], [1.0, 2.0]])] + polys[3:5]
    ptr = np.cumsum([0] + [len(p) for p in stuck])
    assert resample_each(np.concatenate(stuck), ptr)[1] == 3
    builder = NetworkBuilder()
    for p in stuck[:3]:
        builder.add(p, 0)
    assert [len(p) for p in builder.polys] == [len(resample(p)) for p in stuck[:3]]
    builder.add(stuck[3], 0)
    with pytest.raises(ValueError, match="lane 3: lane polyline needs two distinct points"):
        builder.polys


def test_fillet_corners_match_numpy():
    """The kerb fillets painted by ``raster.fillet_corners`` against its numpy version."""
    from dstenv.sim.raster import Surface, fillet_corners
    from dstenv.sim.types import MapClass

    def ref(raster, surface, face, r, res):
        x0, x1, y0, y1 = face
        for cx, cy, sx, sy in ((x0, y0, 1, 1), (x1, y0, -1, 1), (x0, y1, 1, -1),
                               (x1, y1, -1, -1)):
            c_lo, c_hi = (int(np.floor(min(cx, cx + sx * r) / res)),
                          int(np.ceil(max(cx, cx + sx * r) / res)))
            r_lo, r_hi = (int(np.floor(min(cy, cy + sy * r) / res)),
                          int(np.ceil(max(cy, cy + sy * r) / res)))
            cols, rows = np.arange(c_lo, c_hi), np.arange(r_lo, r_hi)
            xc, yc = (cols + 0.5) * res, (rows + 0.5) * res
            ox, oy = cx + sx * r, cy + sy * r
            m = (((xc[None, :] - ox) ** 2 + (yc[:, None] - oy) ** 2 > r * r)
                 & ((xc[None, :] - ox) * sx < 0) & ((yc[:, None] - oy) * sy < 0)
                 & ((xc - cx) * sx >= 0)[None, :] & ((yc - cy) * sy >= 0)[:, None])
            rr, cc = np.nonzero(m)
            rr, cc = rows[rr], cols[cc]
            ok = (rr >= 0) & (rr < raster.shape[0]) & (cc >= 0) & (cc < raster.shape[1])
            raster[rr[ok], cc[ok]] = MapClass.ROAD
            surface[rr[ok], cc[ok]] = Surface.ROAD

    rng = np.random.default_rng(9)
    for _ in range(40):
        res = float(rng.choice([0.1, 0.2, 0.33]))
        x0, y0 = rng.uniform(-5, 60, 2)  # some corners off the raster
        face = (x0, x0 + rng.uniform(10, 60), y0, y0 + rng.uniform(10, 60))
        r = float(rng.uniform(1, 6))
        a = [np.full((300, 320), MapClass.INTERMEDIATE, np.uint8) for _ in range(2)]
        b = [np.full((300, 320), Surface.SIDEWALK, np.uint8) for _ in range(2)]
        fillet_corners(a[0], b[0], face, r, res)
        ref(a[1], b[1], face, r, res)
        np.testing.assert_array_equal(a[0], a[1])
        np.testing.assert_array_equal(b[0], b[1])
    assert (a[0] == MapClass.ROAD).any()  # the fillets painted something
