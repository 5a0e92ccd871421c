"""The counter-based beam draws have NumPy's distributions (normal with its tails,
Bernoulli dropout) and depend on the key and the beam index only."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from dstenv.sensing.draws import beam_dropout, beam_normal_pair, stream_keys


@pytest.mark.parametrize("half", [0, 1])
def test_beam_normal_pair_gives_two_normals_of_the_given_scales(half):
    key = stream_keys(np.random.default_rng(5), 1)[0]
    x = beam_normal_pair(key, 1_000_000, 0.02, 0.5)[half]
    scale = (0.02, 0.5)[half]
    assert x.shape == (1_000_000,) and np.isfinite(x).all()
    assert abs(x.mean()) < 5 * scale / 1000  # 5 standard errors
    assert x.std() == pytest.approx(scale, rel=3e-3)
    # the wedge and tail branches (~1 % of samples) shape the tails: P(|z| > 3) = 0.0027
    assert (np.abs(x) > 3 * scale).mean() == pytest.approx(2 * stats.norm.sf(3.0), rel=0.06)
    assert stats.kstest(x[:200_000] / scale, "norm").pvalue > 1e-3
    assert np.abs(x).max() > 4.5 * scale  # the tail beyond the ziggurat's last layer


def test_the_two_normals_of_a_pair_are_independent():
    key = stream_keys(np.random.default_rng(3), 1)[0]
    a, b = beam_normal_pair(key, 400_000, 1.0, 1.0)
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.01
    assert abs(np.corrcoef(a ** 2, b ** 2)[0, 1]) < 0.01  # not just uncorrelated
    assert abs(np.corrcoef(a[1:], a[:-1])[0, 1]) < 0.01  # nor neighbouring beams
    # the 2-D law: the share of each quadrant is a quarter
    assert ((a > 0) & (b > 0)).mean() == pytest.approx(0.25, abs=0.004)


def test_beam_dropout_is_independent_bernoulli():
    key = stream_keys(np.random.default_rng(7), 1)[0]
    keep = beam_dropout(key, 1_000_000, 0.1)
    assert keep.dtype == np.bool_ and keep.shape == (1_000_000,)
    drop = ~keep
    assert drop.mean() == pytest.approx(0.1, abs=0.0015)  # 5 standard errors
    assert drop[1:][drop[:-1]].mean() == pytest.approx(0.1, abs=0.005)  # no clumping
    # gaps between drops are geometric: P(gap >= 10) = 0.9 ** 10
    gaps = np.diff(np.flatnonzero(drop)) - 1
    assert (gaps >= 10).mean() == pytest.approx(0.9 ** 10, abs=0.01)
    assert beam_dropout(key, 100, 0.0).all() and not beam_dropout(key, 100, 1.0).any()


def test_beam_draws_depend_on_key_and_index_only():
    keys = stream_keys(np.random.default_rng(1), 2)
    assert keys.dtype == np.uint64 and keys[0] != keys[1]
    assert np.array_equal(stream_keys(np.random.default_rng(1), 2), keys)
    a, b = beam_normal_pair(keys[0], 5000, 1.0, 2.0)
    a2, b2 = beam_normal_pair(keys[0], 300, 1.0, 2.0)
    assert np.array_equal(a2, a[:300]) and np.array_equal(b2, b[:300])  # a prefix
    assert not np.array_equal(beam_normal_pair(keys[1], 300, 1.0, 2.0)[0], a[:300])
    keep = beam_dropout(keys[1], 50_000, 0.05)
    assert np.array_equal(beam_dropout(keys[1], 3000, 0.05), keep[:3000])
    assert not np.array_equal(beam_dropout(keys[0], 50_000, 0.05), keep)


def test_one_word_step_and_rest_are_beam_normal_pair():
    from dstenv.sensing.draws import beam_normal_rest, beam_normal_words

    key = np.uint64(987654321)
    a, b = beam_normal_words(key, 20000)
    rejected = np.isnan(a) | np.isnan(b)
    assert 100 < rejected.sum() < 800  # ~1 % a half
    for k in np.flatnonzero(np.isnan(a)):
        a[k] = beam_normal_rest(key, k, 0)
    for k in np.flatnonzero(np.isnan(b)):
        b[k] = beam_normal_rest(key, k, 1)
    ref_a, ref_b = beam_normal_pair(key, 20000, 0.5, 2.0)
    np.testing.assert_array_equal(0.0 + 0.5 * a, ref_a)
    np.testing.assert_array_equal(0.0 + 2.0 * b, ref_b)
