"""Observation modes of :class:`~dstenv.envs.DSTGridEnv`: a dict registry.

Each mode turns a :class:`~dstenv.frame.Frame` into one array and declares its
space. Add a mode by adding an :class:`ObservationMode` to :data:`OBSERVATIONS`.

========== ======================= =========================================================
mode       space                   content
========== ======================= =========================================================
pignistic  (5, H, W) float32 [0,1] BetP over ``dstenv.dst.CLASSES`` at t
fcn10      (10, H, W) float32      BetP at t then t-1 (the paper's FCN input)
masses     (32, H, W) float32      raw masses, index = subset bitmask (N=1 W=2 I=4 S=8 M=16)
image      (4, H, W) uint8 [0,255] round(255 * BetP) of navigable, building, static, moving
========== ======================= =========================================================

``image`` is what stable-baselines3's ``CnnPolicy`` takes without options
(channel-first uint8, 4 channels; grids of at least 36 x 36 for NatureCNN). It drops
the ``non_navigable`` channel because the five BetP values sum to 1:
``non_navigable = 1 - sum(image) / 255`` up to rounding, so nothing is lost.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from gymnasium import spaces

from dstenv.dst import CLASSES, NUM_SETS
from dstenv.frame import Frame
from dstenv.registry import Registry

__all__ = ["ObservationMode", "OBSERVATIONS", "IMAGE_CLASSES", "observation_mode", "SECTION"]

#: The classes mapped to the ``image`` channels, in channel order.
IMAGE_CLASSES: tuple[str, ...] = ("navigable", "building", "static", "moving")
_IMAGE_INDEX = np.array([CLASSES.index(c) for c in IMAGE_CLASSES])


@dataclass(frozen=True)
class ObservationMode:
    """One observation mode.

    Attributes:
        channels: number of channels C of the ``(C, H, W)`` observation.
        dtype: numpy dtype of the observation.
        high: upper bound of every value (lower bound 0).
        needs_masses: the frame must carry its masses.
        build: ``frame -> (C, H, W) array`` of ``dtype``.
    """

    channels: int
    dtype: type
    high: float
    needs_masses: bool
    build: Callable[[Frame], np.ndarray]

    def space(self, shape: tuple[int, int]) -> spaces.Box:
        """The ``Box`` of observations for an ``(H, W)`` grid."""
        return spaces.Box(0, self.high, (self.channels, *shape), dtype=self.dtype)


def _unit(x: np.ndarray) -> np.ndarray:
    # float32 rounding can leave BetP a hair outside [0, 1]; the space is closed
    return np.clip(x, 0.0, 1.0, out=np.empty(x.shape, np.float32))


@numba.njit(cache=True)
def _quantise(betp: np.ndarray, index: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    # one pass: round(255 * clip(p, 0, 1)) (ties up), the hot path of the image mode
    for c in range(index.shape[0]):
        src = betp[index[c]]
        for i in range(src.shape[0]):
            for j in range(src.shape[1]):
                v = src[i, j] * 255.0 + 0.5
                out[c, i, j] = 0 if v < 0.0 else (255 if v >= 255.0 else np.uint8(v))


def _image(frame: Frame) -> np.ndarray:
    betp = np.ascontiguousarray(frame.pignistic, dtype=np.float32)
    out = np.empty((len(_IMAGE_INDEX), *betp.shape[1:]), np.uint8)
    _quantise(betp, _IMAGE_INDEX, out)
    return out


def _pignistic(frame: Frame) -> np.ndarray:
    return _unit(frame.pignistic)


def _fcn10(frame: Frame) -> np.ndarray:
    return _unit(frame.fcn_input())


def _masses(frame: Frame) -> np.ndarray:
    if frame.masses is None:
        raise RuntimeError("observation 'masses' needs frames with masses (frame.masses config)")
    return _unit(frame.masses)


#: mode name -> :class:`ObservationMode`
OBSERVATIONS: Registry[ObservationMode] = Registry("mode", "observation.type", {
    "pignistic": ObservationMode(len(CLASSES), np.float32, 1.0, False, _pignistic),
    "fcn10": ObservationMode(2 * len(CLASSES), np.float32, 1.0, False, _fcn10),
    "masses": ObservationMode(NUM_SETS, np.float32, 1.0, True, _masses),
    "image": ObservationMode(len(IMAGE_CLASSES), np.uint8, 255, False, _image),
})


def observation_mode(name: str) -> ObservationMode:
    """Look up a mode, with an error naming the known ones."""
    return OBSERVATIONS.get(name)


def _known_type(c: dict[str, Any]) -> bool:
    """``observation.type``: a grid mode or ``dict`` (the error names both kinds)."""
    from dstenv.config import ConfigError

    if c["type"] == "dict" or c["type"] in OBSERVATIONS:
        return True
    raise ConfigError(f"observation.type: unknown mode {c['type']!r}; known: "
                      f"{', '.join([*OBSERVATIONS, 'dict'])}")


def _section() -> "object":
    from dstenv.config import Section

    from dstenv.config import between

    # choices read at validation time, so a mode added to OBSERVATIONS is accepted
    return Section(default_observation_config, {
        "route_points": between(0, 64),
        "route_spacing": between(0.0, 100.0, "m", lo_open=True),
    }, (
        ("type", _known_type, "unknown mode"),
        ("grid", lambda c: observation_mode(c["grid"]) is not None, "unknown grid mode"),))


def default_observation_config() -> dict[str, Any]:
    """The ``observation`` section (units in comments)."""
    return {
        # "image" | "pignistic" | "fcn10" | "masses" | "dict" (grid + ego + route,
        # dstenv.envs.navigation)
        "type": "image",
        "grid": "image",  # the grid mode inside "dict" (any mode above but dict)
        "route_points": 8,  # "dict": K route points ahead ...
        "route_spacing": 5.0,  # [m] ... this far apart
    }


#: The ``observation`` section of the env configuration.
SECTION = _section()
