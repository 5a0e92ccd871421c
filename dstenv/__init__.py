"""dstenv: Dempster-Shafer perception grids from a fast 2-D urban simulator.

Importing :mod:`dstenv` registers the Gymnasium environments (``DSTGrid-v0`` and
variants); the numerical core (:mod:`dstenv.dst`, :mod:`dstenv.sim`,
:mod:`dstenv.sensing`) never imports gymnasium itself.
"""

from __future__ import annotations

from pathlib import Path

from dstenv import _jitcache

__version__ = "0.2.0.dev0"

__all__ = ["__version__"]

# numba's cache must see when a kernel's imported modules change (see _jitcache)
_jitcache.register_package("dstenv", Path(__file__).parent)
_jitcache.install_when_imported()


def _register() -> None:
    try:
        from dstenv.envs.registration import register_envs

        register_envs()
    except ImportError:  # gymnasium missing: the numpy core still works
        return


_register()
