"""Counter-based Gaussian and uniform draws for the 3-D LIDAR's ~130,000 returns a sweep.

Beam ``k`` of stream ``key`` takes the 64-bit words ``w_0 = mix(key + (k + 1) G)``
(SplitMix64's ``k``-th output, ``G`` its golden-ratio increment) and, for the 1 % of
normal samples that need more, ``mix(w_0 + j G)``, j = 1, 2, ... A beam's draws
depend on its index alone and the one-word samples of a sweep are a loop without a
bit generator's state (faster than ``Generator.normal`` on bulk words, see
``docs/realism-lidar.md``). The normal is NumPy's 256-layer ziggurat
(``random_standard_normal``, with NumPy's tables as numba ships them) on those words:
the same distribution as ``Generator.normal``, not the same numbers; the uniform is
``Generator.random``'s 53-bit double. The keys come from the caller's ``Generator``
(:func:`stream_keys`), so one seed gives one sweep (``tests/sensing/test_draws.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba.np.random._constants import (
    fi_double,
    ki_double,
    wi_double,
    ziggurat_nor_inv_r,
    ziggurat_nor_r,
)

__all__ = ["stream_keys", "beam_normal", "beam_uniform"]

_TO_DOUBLE = 1.0 / 9007199254740992.0  # 2**-53: NumPy's next_double
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # SplitMix64's increment


def stream_keys(rng: np.random.Generator, n: int) -> np.ndarray:
    """``(n,) uint64`` keys of independent counter streams, drawn from ``rng``."""
    return rng.integers(0, np.iinfo(np.int64).max, size=n, dtype=np.int64).astype(np.uint64)


@numba.njit(cache=True, inline="always")
def _mix(z):  # pragma: no cover - numba
    """SplitMix64's finaliser (Steele, Lea, Flood 2014)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True)
def beam_uniform(key, n):  # pragma: no cover - numba
    """``(n,) float64`` uniforms on [0, 1) (53 bits, as ``Generator.random``): the first
    word ``w_0`` of beams ``0 .. n-1`` of stream ``key``."""
    out = np.empty(n)
    for k in range(n):
        out[k] = (_mix(key + np.uint64(k + 1) * _GOLDEN) >> np.uint64(11)) * _TO_DOUBLE
    return out


@numba.njit(cache=True)
def beam_normal(key, n, scale):  # pragma: no cover - numba
    """``(n,) float64`` normals of standard deviation ``scale`` for beams ``0 .. n-1`` of
    stream ``key``: NumPy's ziggurat on each beam's words. The one-word samples (99 %)
    in a loop that vectorises, the rest by :func:`_beam_normal_slow`."""
    out = np.empty(n)
    for k in range(n):
        r = _mix(key + np.uint64(k + 1) * _GOLDEN)
        idx = r & np.uint64(0xFF)
        rabs = (r >> np.uint64(9)) & np.uint64(0x000FFFFFFFFFFFFF)
        x = float(np.int64(rabs)) * wi_double[idx]
        x = -x if (r >> np.uint64(8)) & np.uint64(1) else x
        out[k] = x if rabs < ki_double[idx] else np.nan
    for k in range(n):
        if not out[k] == out[k]:
            out[k] = _beam_normal_slow(_mix(key + np.uint64(k + 1) * _GOLDEN))
    for k in range(n):
        out[k] = 0.0 + scale * out[k]
    return out


@numba.njit(cache=True)
def _beam_normal_slow(base):  # pragma: no cover - numba
    """NumPy's random_standard_normal on a beam's words: ``base`` (its first word),
    then ``mix(base + j G)``, j = 1, 2, ..."""
    j = np.uint64(0)
    while True:
        r = base if j == 0 else _mix(base + j * _GOLDEN)
        j += np.uint64(1)
        idx = int(r & np.uint64(0xFF))
        r >>= np.uint64(8)
        rabs = (r >> np.uint64(1)) & np.uint64(0x000FFFFFFFFFFFFF)
        x = float(np.int64(rabs)) * wi_double[idx]
        if r & np.uint64(1):
            x = -x
        if rabs < ki_double[idx]:
            return x
        if idx == 0:  # the tail beyond r
            while True:
                u1 = (_mix(base + j * _GOLDEN) >> np.uint64(11)) * _TO_DOUBLE
                u2 = (_mix(base + (j + np.uint64(1)) * _GOLDEN) >> np.uint64(11)) * _TO_DOUBLE
                j += np.uint64(2)
                xx = -ziggurat_nor_inv_r * math.log1p(-u1)
                yy = -math.log1p(-u2)
                if yy + yy > xx * xx:
                    if (rabs >> np.uint64(8)) & np.uint64(1):
                        return -(ziggurat_nor_r + xx)
                    return ziggurat_nor_r + xx
        u = (_mix(base + j * _GOLDEN) >> np.uint64(11)) * _TO_DOUBLE  # the wedge
        j += np.uint64(1)
        if (fi_double[idx - 1] - fi_double[idx]) * u + fi_double[idx] < math.exp(-0.5 * x * x):
            return x
