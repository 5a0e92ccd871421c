"""The torch batched update equals the numba filter, grid by grid."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dstenv.dst import DSTParams, PerceptionGridFilter
from dstenv.dst.batched import BatchedGridFilter


def _compare(fs, bf, betp, tol=1e-5):
    for b, f in enumerate(fs):
        np.testing.assert_allclose(betp[b].numpy(), f.pignistic(), atol=tol)
        np.testing.assert_allclose(bf.masses[b].numpy(), f.masses, atol=tol)
        np.testing.assert_allclose(bf.zeta[b].numpy(), f.zeta, atol=tol)


@pytest.mark.parametrize("params", [DSTParams.default(), DSTParams.paper()])
def test_batched_update_matches_the_numba_kernel_over_many_steps(params):
    rng = np.random.default_rng(0)
    b, h, w = 3, 40, 34
    fs = [PerceptionGridFilter((h, w), params, 0.5) for _ in range(b)]
    bf = BatchedGridFilter(b, (h, w), params, 0.5)
    for step in range(25):
        # blobs of codes, so that evidence accumulates and zeta moves in both directions
        sensor = rng.integers(0, 3, (b, h // 2, w // 2)).repeat(2, 1).repeat(2, 2).astype(np.uint8)
        gis = rng.integers(0, 4, (b, h // 2, w // 2)).repeat(2, 1).repeat(2, 2).astype(np.uint8)
        motion = rng.normal([0.4, 0.0, 0.0], [0.4, 0.2, 0.08], (b, 3))
        motion[1] = 0.0  # one grid stands still
        if step == 0:
            motion = None
        betp = bf.update(sensor, gis, motion)
        for k, f in enumerate(fs):
            f.update(sensor[k], gis[k], None if motion is None else tuple(motion[k]), copy=False)
        _compare(fs, bf, betp)
        if step == 12:  # restart grid 2 only
            bf.reset(np.array([False, False, True]))
            fs[2].reset()
    assert float(bf.zeta.max()) > 0  # the accumulator was exercised
    sums = bf.masses.sum(dim=1)
    assert torch.allclose(sums, torch.ones_like(sums), atol=1e-5)


def test_batched_update_rejects_bad_inputs():
    bf = BatchedGridFilter(2, (8, 6))
    ok = np.zeros((2, 8, 6), np.uint8)
    with pytest.raises(ValueError, match="sensor_states must have shape"):
        bf.update(ok[:1], ok)
    with pytest.raises(ValueError, match="map_classes holds codes outside 0..3"):
        bf.update(ok, ok + 4)
    with pytest.raises(ValueError, match="ego_motion must have shape"):
        bf.update(ok, ok, np.zeros((2, 2)))
    # attack 16: float codes were truncated, NaN motion an index error, a strided
    # tensor a view error, and bad devices or reset masks torch's own errors
    before = bf.masses.clone()
    with pytest.raises(ValueError, match="sensor_states must hold integer codes, got "
                                         "torch.float32"):
        bf.update(torch.zeros((2, 8, 6)) + 0.7, ok)
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError, match="ego_motion must be finite"):
            bf.update(ok, ok, np.array([[bad, 0, 0], [0, 0, 0]]))
    assert torch.equal(bf.masses, before)  # refused before any change
    codes = torch.from_numpy(np.random.default_rng(0).integers(0, 3, (2, 8, 12), np.uint8))
    strided, dense = BatchedGridFilter(2, (8, 6)), BatchedGridFilter(2, (8, 6))
    np.testing.assert_array_equal(strided.update(codes[:, :, ::2], ok).numpy(),
                                  dense.update(codes[:, :, ::2].contiguous(), ok).numpy())
    with pytest.raises(ValueError, match=r"reset: which must be a \(2,\) bool mask"):
        bf.reset(torch.tensor([0, 2]))
    with pytest.raises(ValueError, match="device 'tpu0': not usable here"):
        BatchedGridFilter(2, (8, 6), device="tpu0")
