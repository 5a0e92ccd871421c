"""dstenv: Dempster-Shafer perception grids from a fast 2-D urban simulator.

Importing :mod:`dstenv` registers the Gymnasium environments (``DSTGrid-v0`` and
variants); the numerical core (:mod:`dstenv.dst`, :mod:`dstenv.sim`,
:mod:`dstenv.sensing`) never imports gymnasium itself.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]


def _register() -> None:
    try:
        from dstenv.envs.registration import register_envs

        register_envs()
    except ImportError:  # gymnasium missing: the numpy core still works
        return


_register()
