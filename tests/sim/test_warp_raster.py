"""The warp's raster re-sampling skips uniform source tiles (issue 16) and still gives
every cell of the plain fixed-point scheme, bit for bit."""

from __future__ import annotations

import numba as nb
import numpy as np
import pytest

from dstenv.sim.warp import Warp, _tile_classes


@nb.njit(cache=True)
def _plain(src, out, q, res, fill, step):  # pragma: no cover - numba
    """The scheme without the shortcut: every ``step``-th column evaluated exactly,
    fixed-point steps in between, each cell's bounds tested."""
    h, w = src.shape
    n_r, n_c = out.shape
    for r in range(n_r):
        v = (r + 0.5) * res - q[11] - q[13]
        u = 0.5 * res - q[10] - q[12]
        x2, y2 = q[6] * u + q[7] * v + q[10], q[8] * u + q[9] * v + q[11]
        ya = y2 - q[3] * np.sin(q[4] * x2 + q[5])
        xa = x2 - q[0] * np.sin(q[1] * ya + q[2])
        for c0 in range(0, n_c, step):
            c1 = min(c0 + step, n_c)
            u = (c1 + 0.5) * res - q[10] - q[12]
            x2, y2 = q[6] * u + q[7] * v + q[10], q[8] * u + q[9] * v + q[11]
            yb = y2 - q[3] * np.sin(q[4] * x2 + q[5])
            xb = x2 - q[0] * np.sin(q[1] * yb + q[2])
            n = c1 - c0
            xi, yi = np.int64(xa / res * 65536.0), np.int64(ya / res * 65536.0)
            dx = np.int64((xb - xa) / res * 65536.0 / n)
            dy = np.int64((yb - ya) / res * 65536.0 / n)
            xa, ya = xb, yb
            for k in range(n):
                cc, rr = (xi + k * dx) >> 16, (yi + k * dy) >> 16
                out[r, c0 + k] = src[rr, cc] if 0 <= rr < h and 0 <= cc < w else fill


def _city_like(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Large uniform areas with straight edges (streets, blocks) and a few specks."""
    src = np.full(shape, 3, np.uint8)
    for _ in range(12):
        r0, c0 = rng.integers(0, shape[0]), rng.integers(0, shape[1])
        src[r0:r0 + rng.integers(5, 60), :] = 2
        src[:, c0:c0 + rng.integers(5, 60)] = 2
    specks = rng.integers(0, src.size, 40)
    src.ravel()[specks] = rng.integers(0, 5, 40)
    return src


@pytest.mark.parametrize("seed", range(6))
def test_warp_raster_equals_the_plain_scheme(seed):
    # strong bends and shear too (bend slope 0.3, 30 deg): the curvature bound must hold
    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(300, 700)), int(rng.integers(300, 700)))
    res = 0.2
    size = np.array([shape[1] * res, shape[0] * res])
    lx, ly = rng.uniform(40.0, 300.0, 2)
    slope = rng.uniform(0.0, 0.3, 2)
    warp = Warp(float(slope[0] * lx / (2 * np.pi)), float(lx), float(rng.uniform(0, 6.3)),
                float(slope[1] * ly / (2 * np.pi)), float(ly), float(rng.uniform(0, 6.3)),
                float(np.deg2rad(rng.uniform(-30, 30))), size / 2, np.zeros(2))
    warp.shift = rng.uniform(-5.0, 5.0, 2)
    src = _city_like(rng, shape)
    out_shape = (shape[0] + 80, shape[1] + 60)
    ref = np.empty(out_shape, np.uint8)
    _plain(src, ref, warp._params(), res, np.uint8(7), 16)
    got = warp.raster(src, out_shape, res, 7)
    assert np.array_equal(got, ref)
    assert (got == 7).any() and len(np.unique(got)) > 3  # border fill and specks taken


def test_tile_classes_of_a_hand_made_raster():
    src = np.zeros((5, 7), np.uint8)
    src[:, 4:] = 2
    src[4, 5] = 1  # a tile of the partial last row becomes mixed
    src[4, 6] = 1  # the one-cell corner tile is uniform
    src[0, 0] = 3  # and so does the first
    assert _tile_classes(src, 2).tolist() == [[-1, 0, 2, 2], [0, 0, 2, 2], [0, 0, -1, 1]]
