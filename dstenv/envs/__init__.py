"""Gymnasium environments on DST perception grids: ``DSTGrid-v0`` and variants.

``import dstenv`` registers the ids (:mod:`dstenv.envs.registration`); the classes
load lazily so that registering stays cheap.
"""

from __future__ import annotations

from dstenv._lazy import lazy_attributes

__all__ = ["DSTGridEnv", "DSTGridObservation", "register_envs"]

_WHERE = {
    "DSTGridEnv": "dstgrid",
    "DSTGridObservation": "wrapper",
    "register_envs": "registration",
}
__getattr__, __dir__ = lazy_attributes(__name__, _WHERE)
