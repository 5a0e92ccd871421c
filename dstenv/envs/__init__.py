"""Gymnasium environments on DST perception grids: ``DSTGrid-v0`` and variants.

``import dstenv`` registers the ids (:mod:`dstenv.envs.registration`); the classes
load lazily so that registering stays cheap.
"""

from __future__ import annotations

from typing import Any

__all__ = ["DSTGridEnv", "DSTGridObservation", "register_envs"]

_LAZY = {
    "DSTGridEnv": "dstenv.envs.dstgrid",
    "DSTGridObservation": "dstenv.envs.wrapper",
    "register_envs": "dstenv.envs.registration",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'dstenv.envs' has no attribute {name!r}")
