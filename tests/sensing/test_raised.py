"""The ground walk's distance bound: against brute force, per cell and per block."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sensing.raised import raised_distance


def test_raised_distance_is_the_chessboard_distance_less_one_capped():
    """Against brute force: min over raised cells of max(|di|, |dj|), less one, clipped
    to [0, 255]; rasters of one row or column, none raised, and one with a raised cell
    farther than the cap (the int16 passes cap at 256)."""
    rng = np.random.default_rng(7)
    cases = [(rng.random(shape) < dens).astype(np.uint8) * 3
             for shape in ((1, 1), (1, 9), (9, 1), (2, 2), (23, 31), (64, 48))
             for dens in (0.0, 0.01, 0.1, 0.6)]
    far = np.zeros((3, 600), np.uint8)
    far[1, 0] = 3
    cases.append(far)
    for raster in cases:
        got = raised_distance(raster, 3)
        ii, jj = np.nonzero(raster == 3)
        if len(ii) == 0:
            want = np.full(raster.shape, 255, np.uint8)
        else:
            gi, gj = np.indices(raster.shape)
            cheb = np.maximum(np.abs(gi[..., None] - ii), np.abs(gj[..., None] - jj)).min(axis=-1)
            want = np.clip(cheb - 1, 0, 255).astype(np.uint8)
        np.testing.assert_array_equal(got, want, err_msg=str(raster.shape))
    assert raised_distance(far, 3)[1, 300] == 255 and raised_distance(far, 3)[1, 200] == 199


def test_raised_distance_of_blocks_bounds_the_cell_distance():
    """Blocks of 2**s cells: the value e of a block is the chessboard distance between
    blocks less one, and ``e << s`` never exceeds any of its cells' own (uncapped)
    bound, the cap of 255 blocks included; tight to within 2 * 2**s - 1 cells where
    it is not capped."""
    rng = np.random.default_rng(3)
    for shape in ((1, 1), (5, 3), (33, 47), (64, 64), (3, 600)):
        for dens in (0.0, 0.003, 0.05, 0.5):
            raster = (rng.random(shape) < dens).astype(np.uint8) * 3
            ii, jj = np.nonzero(raster == 3)
            if len(ii):  # each cell's own bound, uncapped (brute force)
                gi, gj = np.indices(shape)
                fine = np.maximum(np.abs(gi[..., None] - ii),
                                  np.abs(gj[..., None] - jj)).min(axis=-1) - 1
                fine = np.maximum(fine, 0)
            else:
                fine = np.full(shape, 1 << 20)
            for s in (1, 2, 3):
                b = 1 << s
                blocks = raised_distance(raster, 3, s)
                assert blocks.shape == (-(-shape[0] // b), -(-shape[1] // b))
                # the block raster's own bound: blocks holding a raised cell are raised
                any_b = np.zeros(blocks.shape, np.uint8)
                any_b[ii // b, jj // b] = 3
                np.testing.assert_array_equal(blocks, raised_distance(any_b, 3))
                per_cell = np.repeat(np.repeat(blocks.astype(np.int64) << s, b, 0), b, 1)
                per_cell = per_cell[:shape[0], :shape[1]]
                assert (per_cell <= fine).all(), (shape, dens, s)
                uncapped = (blocks < 255) & (blocks > 0)
                cells = np.repeat(np.repeat(uncapped, b, 0), b, 1)[:shape[0], :shape[1]]
                assert (fine - per_cell)[cells].max(initial=0) <= 2 * b - 1
    with pytest.raises(ValueError, match="shift"):
        raised_distance(np.zeros((2, 2), np.uint8), 3, -1)
