"""Returns that fade with range and incidence (dstenv.sensing.fading): the measured loss
on hand-built scenes equals the model's probability; off by default; one seed, one sweep."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.sensing.fading import detection_probability, incidence_cosine
from dstenv.sensing.lidar3d import REFLECTANCE, SURFACES, Hdl64

from .worlds import agents, rect_map

IDEAL = {"range_noise": 0.0, "dropout": 0.0, "intensity_noise": 0.0, "spin_rate": 0.0,
         "min_range": 0.0}
AGENT = SURFACES.index("agent")


def _sweep(world, ag, seed=0, **kw):
    lidar = Hdl64({"model": "hdl64", "hdl64": {**IDEAL, **kw}})
    return lidar.sweep(world, ag, np.zeros(3), np.random.default_rng(seed))


def _phi(x):
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


def test_detection_probability_by_hand():
    # rho 0.4, cos 0.5, (140 / 40)^2 = 12.25: s = 2.45, P = Phi(ln 2.45 / 1)
    assert detection_probability(0.4, 0.5, 40.0, 140.0, 1.0) == pytest.approx(
        _phi(math.log(2.45)), abs=1e-12)
    assert detection_probability(0.4, 0.5, 40.0, 0.0, 1.0) == 1.0  # off
    assert detection_probability(0.4, 0.0, 40.0, 140.0, 1.0) == 0.0  # edge-on
    # at s = 1 exactly half the returns survive, whatever sigma
    assert detection_probability(1.0, 1.0, 50.0, 50.0, 0.3) == pytest.approx(0.5)


def test_incidence_cosine_of_a_side_face_and_the_roof():
    box = np.array([10.0, 0.0, 1.0, 0.0, 2.0, 10.0, 0.0, 1.5, 3.0, 0.0, 10.2])  # face x = 8
    # head-on into the face x = 8, level beam: cos = 1; 30 deg in azimuth: cos 30
    assert incidence_cosine(box, 0.0, 0.0, 1.0, 0.0, 0.0, 8.0) == pytest.approx(1.0)
    a = math.radians(30.0)
    t = 8.0 / math.cos(a)
    assert incidence_cosine(box, 0.0, 0.0, math.cos(a), math.sin(a), 0.0, t) == pytest.approx(
        math.cos(a))
    # down at 10 deg onto the roof (inside the footprint): cos = sin 10
    s = -math.tan(math.radians(10.0))
    assert incidence_cosine(box, 0.0, 0.0, 1.0, 0.0, s, 10.0) == pytest.approx(
        math.sin(math.radians(10.0)))


def test_measured_loss_on_a_face_equals_the_model():
    """A wide car face met head-on by a few level-ish channels at 40 m: every return
    on it has about the same strength, so the lost share is 1 - P within the
    binomial error."""
    world = rect_map([], extent=(-60.0, 60.0, -60.0, 60.0))
    car = agents((41.0, 0.0, 0.0, 2.0, 30.0, 0.0))  # face x = 40, 30 m wide, 1.5 m tall
    kw = {"channels": 4, "elevation_top": -0.5, "elevation_bottom": -1.5, "azimuth_step": 0.05}
    clean = _sweep(world, car, **kw)
    faded = _sweep(world, car, seed=3, fade_range=100.0, fade_sigma=0.8, **kw)
    on = clean.surface == AGENT
    p = clean.points[on]
    r = np.linalg.norm(p[:, :3], axis=1)
    cos_inc = 40.0 / r  # the face normal is x; the beam's cosine to it is x / r
    expect = np.mean([detection_probability(REFLECTANCE[AGENT], c, rr, 100.0, 0.8)
                      for c, rr in zip(cos_inc, r)])
    n = on.sum()
    kept = (faded.surface == AGENT).sum() / n
    assert n > 3000 and 0.2 < expect < 0.9  # the test bites: a fraction, not 0 or 1
    assert kept == pytest.approx(expect, abs=4 * math.sqrt(expect * (1 - expect) / n))
    # the road keeps every return
    assert (faded.surface != AGENT).sum() == (clean.surface != AGENT).sum()


def test_grazing_faces_lose_more_than_head_on_ones():
    world = rect_map([], extent=(-60.0, 60.0, -60.0, 60.0))
    kw = {"channels": 8, "elevation_top": 0.0, "elevation_bottom": -3.0, "azimuth_step": 0.05}
    share = []
    for yaw in (0.0, 1.3):  # the 30 m face head-on, then turned 75 deg from the beam
        car = agents((45.0, 0.0, yaw, 1.0, 30.0, 0.0))
        clean = (_sweep(world, car, **kw).surface == AGENT).sum()
        faded = (_sweep(world, car, fade_range=140.0, **kw).surface == AGENT).sum()
        share.append(faded / clean)
    assert share[0] > 0.85 and share[1] < share[0] - 0.2  # head-on: Phi(ln 3.87) = 0.91


def test_off_by_default_same_bits_and_deterministic():
    world = rect_map([(20.0, 30.0, -5.0, 5.0)])
    car = agents((18.0, 6.0, 0.3, 4.5, 1.8, 0.0))
    assert Hdl64({"model": "hdl64"}).config["fade_range"] == 0.0
    base = Hdl64({"model": "hdl64"})
    rng = np.random.default_rng(5)
    a = base.sweep(world, car, np.zeros(3), rng)
    after_a = rng.integers(1 << 30)
    faded = Hdl64({"model": "hdl64", "hdl64": {"fade_range": 60.0}})
    rng = np.random.default_rng(5)
    b = faded.sweep(world, car, np.zeros(3), rng)
    assert rng.integers(1 << 30) == after_a  # the caller's generator advances as before
    c = faded.sweep(world, car, np.zeros(3), np.random.default_rng(5))
    assert np.array_equal(b.points, c.points)
    # fading only removes agent returns: the rest is the same bits
    assert np.array_equal(a.points[a.surface != AGENT], b.points[b.surface != AGENT])
    assert (b.surface == AGENT).sum() < (a.surface == AGENT).sum()


@pytest.mark.parametrize("bad", [{"fade_range": -1.0}, {"fade_sigma": 0.0}])
def test_bad_fade_values_are_named(bad):
    key = next(iter(bad))
    with pytest.raises(ConfigError, match=key):
        Hdl64({"model": "hdl64", "hdl64": bad})
