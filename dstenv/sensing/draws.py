"""NumPy's normal draws, bit for bit, twice as fast (the 3-D LIDAR's range and intensity noise).

A sweep of the 3-D LIDAR draws ~130,000 range-noise and as many intensity-noise
normals. ``Generator.normal`` spends most of its time per call of the bit
generator; here the 64-bit words come in bulk from ``bit_generator.random_raw``
and NumPy's own 256-layer ziggurat runs on them in numba, with NumPy's tables (as
numba ships them for its own ``Generator`` support): the one-word samples (99 %)
in a loop that vectorises, the rest by NumPy's rejection steps. The results and
the generator's state afterwards are exactly those of ``rng.normal(0, scale, n)``
(``tests/sensing/test_draws.py``).

Words are never drawn ahead: a normal needs at least one word, so with ``k`` of
``n`` normals done at most ``n - k`` more are requested; a sample cut short by the
end of a batch is redone from its first word once the next batch arrives.
Bit generators whose raw output is not NumPy's 64-bit word (``MT19937``) take
``Generator.normal`` itself.

Counter-based draws (:func:`beam_normal`, :func:`beam_uniform`), what the 3-D
LIDAR uses now: beam ``k`` of stream ``key`` takes the words ``w_0 = mix(key +
(k + 1) G)`` (SplitMix64's ``k``-th output, ``G`` its golden-ratio increment) and,
for the 1 % of samples that need more, ``mix(w_0 + j G)``, j = 1, 2, ... A beam's
draws depend on its index alone, and the one-word samples of a sweep are one loop
without a bit generator's state. The normal is NumPy's ziggurat above on those
words (same tables, same rejection steps): the same distribution as
``Generator.normal``, not the same numbers. The keys come from the caller's
``Generator`` (:func:`stream_keys`), so one seed gives one sweep.
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

__all__ = ["normal", "stream_keys", "beam_normal", "beam_uniform"]

_RAW64 = (np.random.PCG64, np.random.PCG64DXSM, np.random.Philox, np.random.SFC64)
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
    """``(n,) float64`` uniforms on [0, 1) (53 bits, as ``Generator.random``): word 1
    of beams ``0 .. n-1`` of stream ``key``."""
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


def normal(rng: np.random.Generator, scale: float, n: int) -> np.ndarray:
    """``(n,) float64`` Gaussian draws of standard deviation ``scale``: exactly
    ``rng.normal(0.0, scale, n)``."""
    if not isinstance(rng.bit_generator, _RAW64):
        return rng.normal(0.0, scale, n)
    out = np.empty(n)
    words = rng.bit_generator.random_raw(n)  # the fewest n normals can take
    done, used = _ziggurat(words, out, 0, float(scale))
    while done < n:  # ~1 % rejections: a few short top-ups
        words = np.concatenate([words[used:], rng.bit_generator.random_raw(n - done)])
        done, used = _ziggurat(words, out, done, float(scale))
    return out


@numba.njit(cache=True)
def _fast(words, fast):  # pragma: no cover - numba
    """Each word as a one-word sample (the ziggurat's rectangle, 99 % of them), NaN
    where it is not: a loop without dependencies, which vectorises."""
    for p in range(words.shape[0]):
        r = words[p]
        idx = r & np.uint64(0xFF)
        rabs = (r >> np.uint64(9)) & np.uint64(0x000FFFFFFFFFFFFF)
        x = float(np.int64(rabs)) * wi_double[idx]  # rabs < 2**52: exact
        x = -x if (r >> np.uint64(8)) & np.uint64(1) else x
        fast[p] = x if rabs < ki_double[idx] else np.nan


@numba.njit(cache=True)
def _ziggurat(words, out, k, scale):  # pragma: no cover - numba
    """Fill ``out[k:]`` from ``words``; return ``(k, used)``: the normals now done and
    the words they took (a sample that ran out of words is left for later)."""
    n = out.shape[0]
    m = words.shape[0]
    fast = np.empty(m)
    _fast(words, fast)
    pos = 0
    while k < n and pos < m:
        x = fast[pos]
        if x == x:
            pos += 1
        else:
            x, end = _sample(words, pos)
            if end < 0:  # out of words mid-sample
                return k, pos
            pos = end
        out[k] = 0.0 + scale * x  # NumPy's random_normal: loc + scale * z
        k += 1
    return k, pos


@numba.njit(cache=True)
def _sample(words, pos):  # pragma: no cover - numba
    """One standard normal from ``words[pos:]`` (NumPy's random_standard_normal):
    ``(value, next position)``, or ``(nan, -1)`` if the words run out."""
    m = words.shape[0]
    while pos < m:
        r = words[pos]
        pos += 1
        idx = int(r & np.uint64(0xFF))
        r >>= np.uint64(8)
        rabs = (r >> np.uint64(1)) & np.uint64(0x000FFFFFFFFFFFFF)
        x = float(np.int64(rabs)) * wi_double[idx]
        if r & np.uint64(1):
            x = -x
        if rabs < ki_double[idx]:
            return x, pos
        if idx == 0:  # the tail beyond r: NumPy loops here until it accepts
            while pos + 1 < m:
                xx = -ziggurat_nor_inv_r * math.log1p(-((words[pos] >> np.uint64(11)) * _TO_DOUBLE))
                yy = -math.log1p(-((words[pos + 1] >> np.uint64(11)) * _TO_DOUBLE))
                pos += 2
                if yy + yy > xx * xx:
                    if (rabs >> np.uint64(8)) & np.uint64(1):
                        return -(ziggurat_nor_r + xx), pos
                    return ziggurat_nor_r + xx, pos
            return np.nan, -1
        if pos >= m:
            return np.nan, -1
        u = (words[pos] >> np.uint64(11)) * _TO_DOUBLE  # the wedge of layer idx
        pos += 1
        if (fi_double[idx - 1] - fi_double[idx]) * u + fi_double[idx] < math.exp(-0.5 * x * x):
            return x, pos
    return np.nan, -1
