"""RANSAC's draws are NumPy's: the replayed tail shuffle and triplets."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sensing.ransac import sample_candidates


@pytest.mark.parametrize(("k", "size", "iterations", "seed"), [
    (101_701, 4000, 200, 0), (85_000, 4000, 200, 3), (10_001, 201, 5, 1), (10_001, 200, 5, 1),
    (10_000, 4000, 50, 2), (5000, 4000, 20, 0), (3000, 4000, 20, 0)])
def test_ransac_sample_is_numpys_choice_and_integers(k, size, iterations, seed):
    """The replayed tail shuffle (and the cases left to NumPy) draw exactly what
    ``default_rng(seed).choice(k, size, replace=False)`` then ``.integers`` draw."""
    pick = np.arange(k) * 3 + 7  # any candidate indices
    rng = np.random.default_rng(seed)
    want = pick[rng.choice(k, size, replace=False)] if k > size else pick
    want_tri = rng.integers(0, len(want), size=(iterations, 3))
    got, tri = sample_candidates(pick, size, iterations, seed)
    assert np.array_equal(got, want) and np.array_equal(tri, want_tri)
