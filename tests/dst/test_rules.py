"""Properties of the combination rules and transforms."""

import numpy as np
import pytest

from dstenv.dst import (
    CLASSES, FREE, M, NUM_SETS, OCCUPIED, OMEGA, conjunctive, dempster, discount, mass_within,
    modified_conjunctive, pignistic, specialise, subset_name, vacuous,
)


def random_masses(rng, shape=(4, 5), batch=(), focal=None, empty=False):
    m = rng.random((*batch, NUM_SETS, *shape))
    if not empty:
        m[..., 0, :, :] = 0
    if focal is not None:
        keep = np.zeros(NUM_SETS, bool)
        keep[list(focal)] = True
        m[..., ~keep, :, :] = 0
    return (m / m.sum(axis=-3, keepdims=True)).astype(np.float32)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def test_classes_and_layout():
    assert CLASSES == ("navigable", "non_navigable", "building", "static", "moving")
    assert (FREE, OCCUPIED, OMEGA, M) == (3, 28, 31, 16)
    assert subset_name(25) == "{N,S,M}"


def test_conjunctive_matches_definition_on_one_cell(rng):
    m1, m2 = random_masses(rng, (1, 1)), random_masses(rng, (1, 1))
    expected = np.zeros(NUM_SETS)
    for b in range(NUM_SETS):
        for c in range(NUM_SETS):
            expected[b & c] += float(m1[b, 0, 0]) * float(m2[c, 0, 0])
    np.testing.assert_allclose(conjunctive(m1, m2)[:, 0, 0], expected, atol=1e-6)


def test_dempster_commutative_associative_normalised(rng):
    a, b, c = (random_masses(rng) for _ in range(3))
    ab = dempster(a, b)
    np.testing.assert_allclose(ab, dempster(b, a), atol=1e-6)
    np.testing.assert_allclose(dempster(ab, c), dempster(a, dempster(b, c)), atol=1e-5)
    assert np.all(ab >= 0) and np.all(ab[0] == 0)
    np.testing.assert_allclose(ab.sum(0), 1.0, atol=1e-5)


def test_vacuous_is_identity(rng):
    m = random_masses(rng)
    v = vacuous(m.shape[-2:])
    np.testing.assert_allclose(dempster(v, m), m, atol=1e-6)
    np.testing.assert_allclose(conjunctive(m, v), m, atol=1e-6)
    np.testing.assert_allclose(modified_conjunctive(v, m), m, atol=1e-6)


def test_total_conflict_gives_vacuous():
    a = np.zeros((NUM_SETS, 1, 1), np.float32)
    b = np.zeros_like(a)
    a[FREE] = 1.0
    b[OCCUPIED] = 1.0
    out = dempster(a, b)
    assert out[OMEGA, 0, 0] == 1.0 and out.sum() == 1.0


def test_batch_axes(rng):
    a, b = random_masses(rng, batch=(2, 3)), random_masses(rng, batch=(2, 3))
    out = dempster(a, b)
    assert out.shape == (2, 3, NUM_SETS, 4, 5)
    np.testing.assert_allclose(out[1, 2], dempster(a[1, 2], b[1, 2]), atol=1e-6)
    assert pignistic(a).shape == (2, 3, 5, 4, 5)


def test_modified_rule_routes_conflict():
    past = np.zeros((NUM_SETS, 1, 3), np.float32)
    new = np.zeros_like(past)
    past[FREE, 0, 0], new[OCCUPIED, 0, 0] = 1, 1  # free -> occupied: moving
    past[OCCUPIED, 0, 1], new[FREE, 0, 1] = 1, 1  # occupied -> free: ignorance
    past[4, 0, 2], new[8, 0, 2] = 1, 1  # {I} vs {S}: other conflict, Yager
    out = modified_conjunctive(past, new)
    assert out[M, 0, 0] == 1 and out[OMEGA, 0, 1] == 1 and out[OMEGA, 0, 2] == 1
    np.testing.assert_allclose(out.sum(0), 1.0)


def test_discount_and_specialise(rng):
    m = random_masses(rng)
    d = discount(m, 0.25)
    for bad in (2.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="alpha must lie in"):
            discount(m, bad)
    np.testing.assert_allclose(d[:OMEGA], 0.75 * m[:OMEGA], atol=1e-7)
    np.testing.assert_allclose(d[OMEGA], 0.75 * m[OMEGA] + 0.25, atol=1e-7)
    z = rng.random(m.shape[1:]).astype(np.float32)
    s = specialise(m, z)
    np.testing.assert_allclose(s.sum(0), 1.0, atol=1e-5)
    np.testing.assert_allclose(s[M], m[M], atol=1e-7)  # {M} itself is unchanged
    np.testing.assert_allclose(s[8], m[8] + z * m[24], atol=1e-6)  # {S} <- {S,M}
    np.testing.assert_allclose(s[24], (1 - z) * m[24], atol=1e-6)
    for a in range(1, M):  # a set without M keeps its mass and gains zeta m(A + M)
        np.testing.assert_allclose(s[a], m[a] + z * m[a | M], atol=1e-6)
    np.testing.assert_allclose(specialise(m, np.ones_like(z))[M], m[M], atol=1e-7)


def test_pignistic_sums_to_one_and_hand_value():
    m = np.zeros((NUM_SETS, 1, 1), np.float32)
    m[FREE] = 0.5
    m[OMEGA] = 0.5
    p = pignistic(m)[:, 0, 0]
    np.testing.assert_allclose(p, [0.25 + 0.1, 0.25 + 0.1, 0.1, 0.1, 0.1], atol=1e-7)


def test_mass_within(rng):
    m = random_masses(rng)
    assert mass_within(m, FREE).shape == (4, 5)
    np.testing.assert_allclose(mass_within(m, FREE), m[1] + m[2] + m[3], atol=1e-7)
    np.testing.assert_allclose(mass_within(m, OMEGA), 1.0, atol=1e-5)


def test_bad_shape_is_rejected():
    with pytest.raises(ValueError, match=r"\(\.\.\., 32, H, W\)"):
        dempster(np.zeros((31, 2, 2)), np.zeros((32, 2, 2)))


def test_inputs_that_are_not_mass_functions_are_refused(rng):
    from dstenv.dst import EMPTY

    m = random_masses(rng)
    bad_sum = m * 1.5
    negative = m.copy()
    negative[FREE], negative[OMEGA] = 1.5, -0.5
    nan = m.copy()
    nan[OMEGA, 0, 0] = np.nan
    for bad, match in ((bad_sum, "must sum to 1"), (negative, "finite and >= 0"),
                       (nan, "finite and >= 0"), (np.zeros_like(m), "must sum to 1")):
        with pytest.raises(ValueError, match=match):
            dempster(bad, m)
        with pytest.raises(ValueError, match=match):
            pignistic(bad)
    with pytest.raises(ValueError, match="zeta must lie in"):
        specialise(m, np.full(m.shape[1:], 2.0))
    with pytest.raises(ValueError, match="subset must be a set index"):
        mass_within(m, 40)
    with pytest.raises(ValueError, match="does not fit the cells"):
        discount(m, np.array([0.1, 0.2, 0.3]))
    # a conjunctive result keeps its conflict on the empty set: BetP divides it out
    m1, m2 = vacuous((1, 1)), vacuous((1, 1))
    m1[FREE], m1[OMEGA] = 0.6, 0.4
    m2[OCCUPIED], m2[OMEGA] = 0.7, 0.3
    both = conjunctive(m1, m2)
    assert both[EMPTY, 0, 0] == pytest.approx(0.42)
    np.testing.assert_allclose(pignistic(both), pignistic(dempster(m1, m2)), atol=1e-6)
    np.testing.assert_allclose(pignistic(both).sum(0), 1.0, atol=1e-6)
