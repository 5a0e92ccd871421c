"""Whether this CPU's numpy computes math as libm does (bit-exact tests depend on it)."""

from __future__ import annotations

import functools
import math

import numpy as np


@functools.cache
def numpy_math_is_libm() -> bool:
    """Whether numpy's array ``tan`` / ``exp`` / ``log`` / ``arctan2`` give libm's bits here.

    With AVX-512 numpy dispatches its own SIMD versions, which differ from libm in the
    last bit for ~1 % of inputs (seen on an AMD EPYC with AVX-512, numpy 2.4;
    ``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL"`` brings back libm's bits). numba
    kernels call libm, so a kernel matches the numpy expression it replaced bit for
    bit only where numpy calls libm too (AVX2 CPUs)."""
    x = np.random.default_rng(0).uniform(-10.0, 10.0, 2000)
    y = x[::-1].copy()
    return (np.array_equal(np.tan(x), [math.tan(v) for v in x])
            and np.array_equal(np.exp(x), [math.exp(v) for v in x])
            and np.array_equal(np.log(np.abs(x)), [math.log(abs(v)) for v in x])
            and np.array_equal(np.arctan2(x, y), [math.atan2(u, v) for u, v in zip(x, y)]))
