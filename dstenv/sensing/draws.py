"""Counter-based Gaussian draws and dropout for the 3-D LIDAR's ~130,000 returns a sweep.

Beam ``k`` of stream ``key`` takes the 64-bit word ``w_0 = mix(key + (k + 1) G)``
(SplitMix64's ``k``-th output, ``G`` its golden-ratio increment); the 1 % of normal
samples that need more take further words ``mix(w_0 + j G)``. A beam's draws depend on
its index alone and the one-word samples of a sweep are a loop without a bit
generator's state. :func:`beam_normal_pair` runs NumPy's float32 ziggurat
(``random_standard_normal_f``, NumPy's tables as numba ships them) on the two halves
of ``w_0``: two independent normals a word (the range and the reflectance noise), the
same distribution as ``Generator.normal`` at float32 resolution, not the same
numbers. :func:`beam_dropout` marks dropped beams by geometric gaps (one uniform per
drop, not per beam). The keys come from the caller's ``Generator``
(:func:`stream_keys`), so one seed gives one sweep (``tests/sensing/test_draws.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba.np.random._constants import (
    fi_float,
    ki_float,
    wi_float,
    ziggurat_nor_inv_r_f,
    ziggurat_nor_r_f,
)

__all__ = ["stream_keys", "beam_normal_pair", "beam_normal_words", "beam_normal_rest",
           "beam_dropout", "beam_uniform"]

_TO_DOUBLE = 1.0 / 9007199254740992.0  # 2**-53: NumPy's next_double
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # SplitMix64's increment
_TO_FLOAT = 1.0 / 16777216.0  # 2**-24: NumPy's next_float


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
def beam_normal_pair(key, n, scale_a, scale_b):  # pragma: no cover - numba
    """Two independent ``(n,) float64`` normal streams, of standard deviations
    ``scale_a`` and ``scale_b``, for beams ``0 .. n-1`` of stream ``key``: NumPy's
    float32 ziggurat (``random_standard_normal_f``: 8 bits of layer, a sign, 23 of
    mantissa) on the low and the high half of each beam's first word, so one word
    gives both (the 64-bit mix is the cost: without AVX-512 it does not vectorise).
    The 1 % that need more take the low halves of the words
    ``mix(w_0 + (2 i + h) G)``, i = 1, 2, ..., ``h`` the half (0 low, 1 high)."""
    a, b = beam_normal_words(key, n)
    for k in range(n):
        if not a[k] == a[k]:
            a[k] = beam_normal_rest(key, k, 0)
        if not b[k] == b[k]:
            b[k] = beam_normal_rest(key, k, 1)
    for k in range(n):
        a[k] = 0.0 + scale_a * a[k]
        b[k] = 0.0 + scale_b * b[k]
    return a, b


@numba.njit(cache=True)
def beam_normal_words(key, n):  # pragma: no cover - numba
    """The one-word step of :func:`beam_normal_pair` alone: ``(n,) float64`` standard
    normals ``a`` and ``b`` of beams ``0 .. n-1``, NaN for the ~1 % whose word is
    rejected (:func:`beam_normal_rest` gives those), unscaled. Its loop is the cost
    of the draws; a caller that finishes the rest in its own pass over the beams
    saves two passes (:mod:`dstenv.sensing.lidar3d`)."""
    a = np.empty(n)
    b = np.empty(n)
    for k in range(n):
        w = _mix(key + np.uint64(k + 1) * _GOLDEN)
        a[k] = _zig32_fast(w & np.uint64(0xFFFFFFFF))
        b[k] = _zig32_fast(w >> np.uint64(32))
    return a, b


@numba.njit(cache=True)
def beam_normal_rest(key, k, half):  # pragma: no cover - numba
    """Beam ``k``'s standard normal ``half`` (0: ``a``, 1: ``b``) of stream ``key`` where
    :func:`beam_normal_words` rejected its word (the ziggurat's further words)."""
    return _zig32_slow(_mix(key + np.uint64(k + 1) * _GOLDEN), half)


@numba.njit(cache=True, inline="always")
def _zig32_fast(r):  # pragma: no cover - numba
    """The one-word step of the float32 ziggurat on a 32-bit value ``r`` (held in a
    uint64); NaN where it rejects."""
    idx = r & np.uint64(0xFF)
    rabs = (r >> np.uint64(9)) & np.uint64(0x007FFFFF)
    x = float(np.int64(rabs)) * float(wi_float[idx])
    x = -x if (r >> np.uint64(8)) & np.uint64(1) else x
    return x if rabs < np.uint64(ki_float[idx]) else np.nan


@numba.njit(cache=True)
def _zig32_slow(base, half):  # pragma: no cover - numba
    """NumPy's random_standard_normal_f on the 32-bit values: half ``half`` of
    ``base``, then the low halves of ``mix(base + (2 i + half) G)``, i = 1, 2, ..."""
    i = np.uint64(1)
    r = (base >> np.uint64(32 * half)) & np.uint64(0xFFFFFFFF)
    step = np.uint64(half)
    while True:
        idx = int(r & np.uint64(0xFF))
        rabs = (r >> np.uint64(9)) & np.uint64(0x007FFFFF)
        x = float(np.int64(rabs)) * float(wi_float[idx])
        if (r >> np.uint64(8)) & np.uint64(1):
            x = -x
        if rabs < np.uint64(ki_float[idx]):
            return x
        if idx == 0:  # the tail beyond r
            while True:
                u1 = _low_float(base, i, step)
                u2 = _low_float(base, i + np.uint64(1), step)
                i += np.uint64(2)
                xx = -ziggurat_nor_inv_r_f * math.log1p(-u1)
                yy = -math.log1p(-u2)
                if yy + yy > xx * xx:
                    if (rabs >> np.uint64(8)) & np.uint64(1):
                        return -(ziggurat_nor_r_f + xx)
                    return ziggurat_nor_r_f + xx
        u = _low_float(base, i, step)  # the wedge
        i += np.uint64(1)
        if (float(fi_float[idx - 1]) - float(fi_float[idx])) * u + float(fi_float[idx]) < \
                math.exp(-0.5 * x * x):
            return x
        r = _mix(base + (np.uint64(2) * i + step) * _GOLDEN) & np.uint64(0xFFFFFFFF)
        i += np.uint64(1)


@numba.njit(cache=True, inline="always")
def _low_float(base, i, step):  # pragma: no cover - numba
    """NumPy's next_float (24 bits) from the low half of ``mix(base + (2 i + step) G)``."""
    w = _mix(base + (np.uint64(2) * i + step) * _GOLDEN) & np.uint64(0xFFFFFFFF)
    return float(np.int64(w >> np.uint64(8))) * _TO_FLOAT


@numba.njit(cache=True, inline="always")
def beam_uniform(key, k):  # pragma: no cover - numba
    """Beam ``k``'s uniform in [0, 1) of stream ``key`` (53 bits of its first word, as
    NumPy's next_double)."""
    return float(_mix(key + np.uint64(k + 1) * _GOLDEN) >> np.uint64(11)) * _TO_DOUBLE


@numba.njit(cache=True)
def beam_dropout(key, n, p):  # pragma: no cover - numba
    """``(n,) bool``: True for the beams ``0 .. n-1`` that are kept, each dropped with
    probability ``p`` independently. The gaps between dropped beams are geometric
    (``floor(log(1 - u) / log(1 - p))`` failures before a drop, ``u`` from word ``i``
    of stream ``key``), so a sweep draws about ``n p + 1`` uniforms, not ``n``; a
    prefix of beams gets the same marks whatever ``n``."""
    keep = np.ones(n, np.bool_)
    if p <= 0.0:
        return keep
    if p >= 1.0:
        keep[:] = False
        return keep
    scale = 1.0 / math.log1p(-p)
    pos = -1
    i = np.uint64(1)
    while True:
        u = (_mix(key + i * _GOLDEN) >> np.uint64(11)) * _TO_DOUBLE
        i += np.uint64(1)
        gap = math.floor(math.log1p(-u) * scale)
        if gap >= n - pos:  # also an overflow guard for a huge gap
            return keep
        pos += int(gap) + 1
        if pos >= n:
            return keep
        keep[pos] = False
