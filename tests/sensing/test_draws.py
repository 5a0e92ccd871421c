"""The counter-based beam draws have NumPy's distributions (normal with its tails,
uniform) and depend on the key and the beam index only."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from dstenv.sensing.draws import beam_normal, beam_uniform, stream_keys


def test_beam_normal_is_a_normal_of_the_given_scale():
    key = stream_keys(np.random.default_rng(5), 1)[0]
    x = beam_normal(key, 1_000_000, 0.02)
    assert x.shape == (1_000_000,) and np.isfinite(x).all()
    assert abs(x.mean()) < 5 * 0.02 / 1000  # 5 standard errors
    assert x.std() == pytest.approx(0.02, rel=3e-3)
    # the wedge and tail branches (~1 % of samples) shape the tails: P(|z| > 3) = 0.0027
    assert (np.abs(x) > 3 * 0.02).mean() == pytest.approx(2 * stats.norm.sf(3.0), rel=0.06)
    assert stats.kstest(x[:200_000] / 0.02, "norm").pvalue > 1e-3
    assert np.abs(x).max() > 4.5 * 0.02  # the tail beyond the ziggurat's last layer


def test_beam_draws_depend_on_key_and_index_only():
    keys = stream_keys(np.random.default_rng(1), 2)
    assert keys.dtype == np.uint64 and keys[0] != keys[1]
    assert np.array_equal(stream_keys(np.random.default_rng(1), 2), keys)
    a = beam_normal(keys[0], 5000, 1.0)
    assert np.array_equal(beam_normal(keys[0], 300, 1.0), a[:300])  # a prefix: the same beams
    assert not np.array_equal(beam_normal(keys[1], 300, 1.0), a[:300])
    u = beam_uniform(keys[1], 200_000)
    assert 0.0 <= u.min() and u.max() < 1.0
    assert (u < 0.05).mean() == pytest.approx(0.05, abs=0.002)
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert abs(np.corrcoef(beam_normal(keys[1], 200_000, 1.0), u)[0, 1]) < 0.01
