"""Observation modes: spaces, dtypes and the lossless image encoding."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.dst import CLASSES
from dstenv.envs.observation import IMAGE_CLASSES, OBSERVATIONS, observation_mode
from dstenv.frame import Frame


def _frame(rng: np.random.Generator, h: int = 6, w: int = 7) -> Frame:
    betp = rng.dirichlet(np.ones(5), size=(h, w)).transpose(2, 0, 1).astype(np.float32)
    masses = rng.dirichlet(np.ones(32), size=(h, w)).transpose(2, 0, 1).astype(np.float32)
    return Frame(pignistic=betp, pignistic_prev=betp[::-1].copy(),
                 labels=np.zeros((h, w), np.uint8), visible=np.ones((h, w), bool),
                 sensor=np.zeros((h, w), np.uint8), gis=np.zeros((h, w), np.uint8),
                 ego_pose=np.zeros(3), masses=masses)


@pytest.mark.parametrize("name,channels,dtype", [
    ("pignistic", 5, np.float32), ("fcn10", 10, np.float32),
    ("masses", 32, np.float32), ("image", 4, np.uint8)])
def test_modes_fit_their_space(name, channels, dtype):
    mode = OBSERVATIONS[name]
    f = _frame(np.random.default_rng(0))
    obs = mode.build(f)
    space = mode.space(f.shape)
    assert obs.shape == (channels, 6, 7) and obs.dtype == dtype
    assert space.shape == obs.shape and space.contains(obs)


def test_fcn10_is_t_then_t_minus_1():
    f = _frame(np.random.default_rng(1))
    obs = OBSERVATIONS["fcn10"].build(f)
    assert np.array_equal(obs[:5], f.pignistic) and np.array_equal(obs[5:], f.pignistic_prev)


def test_image_is_lossless_up_to_rounding():
    f = _frame(np.random.default_rng(2))
    img = OBSERVATIONS["image"].build(f).astype(np.float64) / 255
    idx = [CLASSES.index(c) for c in IMAGE_CLASSES]
    assert np.abs(img - f.pignistic[idx]).max() <= 0.5 / 255 + 1e-7
    # the dropped channel is the remainder
    nonnav = 1 - img.sum(axis=0)
    assert np.abs(nonnav - f.pignistic[CLASSES.index("non_navigable")]).max() <= 2 / 255 + 1e-6


def test_values_a_hair_outside_unit_are_clipped():
    f = _frame(np.random.default_rng(3))
    f.pignistic[0, 0, 0] = 1.0000001
    f.pignistic[1, 0, 0] = -1e-8
    obs = OBSERVATIONS["pignistic"].build(f)
    assert obs.max() <= 1.0 and obs.min() >= 0.0


def test_unknown_mode_names_the_known_ones():
    with pytest.raises(ConfigError, match="unknown mode 'rgb'.*pignistic, fcn10, masses, image"):
        observation_mode("rgb")
