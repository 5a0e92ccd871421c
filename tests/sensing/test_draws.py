"""draws.normal is rng.normal bit for bit, and leaves the generator where NumPy would."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sensing.draws import normal


@pytest.mark.parametrize("n", [0, 1, 5, 4096, 300_000])
@pytest.mark.parametrize("seed", [0, 7])
def test_normal_is_numpys_and_so_is_the_state_after(seed, n):
    ours, theirs = np.random.default_rng(seed), np.random.default_rng(seed)
    a, b = normal(ours, 0.02, n), theirs.normal(0.0, 0.02, n)
    assert a.shape == (n,) and np.array_equal(a, b)
    # 300k samples take the ziggurat's wedge and tail branches too (~1 % of samples)
    assert np.array_equal(ours.random(3), theirs.random(3))
    assert np.array_equal(normal(ours, 1.5, 9), theirs.normal(0.0, 1.5, 9))


def test_other_bit_generators():
    for bits in (np.random.Philox, np.random.SFC64, np.random.MT19937):
        ours, theirs = np.random.Generator(bits(3)), np.random.Generator(bits(3))
        assert np.array_equal(normal(ours, 0.1, 1000), theirs.normal(0.0, 0.1, 1000))
        assert ours.random() == theirs.random()
