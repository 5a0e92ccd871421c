"""Synthetic frames for storage tests (no simulator needed)."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.frame import IGNORE_INDEX, Frame


def make_frame(rng: np.random.Generator, h: int = 12, w: int = 10, masses: bool = False,
               step: int = 0, seed: int = 7) -> Frame:
    """A random but valid frame: probabilities sum to 1 per cell, labels 0..4 or ignore."""

    def probs() -> np.ndarray:
        p = rng.random((5, h, w)).astype(np.float32)
        return p / p.sum(axis=0, keepdims=True)

    labels = rng.integers(0, 5, size=(h, w)).astype(np.uint8)
    labels[0, :3] = IGNORE_INDEX
    m = None
    if masses:
        m = rng.random((32, h, w)).astype(np.float32)
        m /= m.sum(axis=0, keepdims=True)
    pign, prev = probs(), probs()
    rng.random((h, w))  # (the draw of a random visibility grid, before format 3)
    sensor = rng.integers(0, 3, size=(h, w)).astype(np.uint8)
    return Frame(
        pignistic=pign, pignistic_prev=prev, labels=labels,
        visible=sensor != 0,  # what the pipeline gives and format-3 readers derive
        sensor=sensor,
        gis=rng.integers(0, 4, size=(h, w)).astype(np.uint8),
        ego_pose=rng.normal(size=3), time=0.1 * step, seed=seed, step=step, masses=m,
    )


@pytest.fixture(name="make_frame")
def make_frame_fixture():
    """The :func:`make_frame` factory."""
    return make_frame


@pytest.fixture(name="shard_attrs")
def shard_attrs_fixture() -> dict:
    """Minimal writer attributes for a 12x10 grid of 0.5 m cells."""
    return {"config": {"grid": {"height": 12, "width": 10, "cell_size": 0.5}}, "seed": 3,
            "split": "train"}


@pytest.fixture
def frames() -> list[Frame]:
    rng = np.random.default_rng(0)
    return [make_frame(rng, masses=True, step=i) for i in range(4)]




class FakePipeline:
    """Frames that are a pure function of (seed, step): enough to test storage logic."""

    resets: list[int] = []

    def __init__(self, config):
        self.h, self.w = config["grid"]["height"], config["grid"]["width"]

    def _frame(self) -> Frame:
        rng = np.random.default_rng([self.seed, self.t])
        p = rng.random((5, self.h, self.w)).astype(np.float32)
        p /= p.sum(axis=0)
        return Frame(pignistic=p, pignistic_prev=p[::-1].copy(),
                     labels=rng.integers(0, 5, (self.h, self.w)).astype(np.uint8),
                     visible=np.zeros((self.h, self.w), bool),  # sensor != 0
                     sensor=np.zeros((self.h, self.w), np.uint8),
                     gis=np.ones((self.h, self.w), np.uint8),
                     ego_pose=np.array([self.t, 0.0, 0.0]), time=0.1 * self.t, seed=self.seed,
                     step=self.t)

    def reset(self, seed):
        FakePipeline.resets.append(seed)
        self.seed, self.t = seed, 0
        return self._frame()

    def step(self, action=None):
        self.t += 1
        return self._frame()


@pytest.fixture
def fake_pipeline(monkeypatch):
    """Replace :class:`dstenv.pipeline.Pipeline` by :class:`FakePipeline` (in this process)."""
    import dstenv.pipeline

    monkeypatch.setattr(dstenv.pipeline, "Pipeline", FakePipeline)
    FakePipeline.resets = []
    return FakePipeline
