"""The RANSAC kernels of the ground-plane fit (:func:`dstenv.sensing.ground.fit_ground_plane`).

Candidates (points near the road), their sample and the triplets of the hypotheses
(NumPy's draws, replayed in numba where NumPy takes a tail shuffle), the best
hypothesis (most candidates within the inlier band, scored in blocks, a hypothesis
dropped once it can no longer win) and the least-squares refit on its inliers. Split
from :mod:`dstenv.sensing.ground` to keep both modules small.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np

__all__ = ["candidates", "sample_candidates", "best_plane", "inlier_moments", "refit"]


@numba.njit(cache=True)
def candidates(xyz, r, fit_range, ego_radius, max_z):  # pragma: no cover - numba
    """``(K,) int64`` indices of the points with ``ego_radius < r < fit_range`` and
    ``z < max_z``, in order."""
    out = np.empty(r.shape[0], np.int64)
    z = xyz[:, 2]
    k = 0
    for p in range(r.shape[0]):  # branch-free: written always, kept by the count
        out[k] = p
        k += (ego_radius < r[p]) & (r[p] < fit_range) & (z[p] < max_z)
    return out[:k]


def sample_candidates(pick: np.ndarray, size: int, iterations: int, seed: int
                      ) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC's draws: at most ``size`` of the candidates ``pick`` (a uniform sample
    without replacement, ``Generator.choice``) and ``(iterations, 3)`` triplets of them
    (``Generator.integers``), from ``default_rng(seed)``.

    Where NumPy's ``choice`` takes a partial Fisher-Yates shuffle (more than 10,000
    candidates, ``size`` above 1/50 of them: the simulated and the real KITTI scans),
    :func:`_tail_sample` replays it and the triplets on the generator's raw words
    (Lemire's bounded draws on its 32-bit stream, as NumPy 2 does): the same picks,
    without ``choice``'s Python overhead (``tests/sensing/test_ransac.py`` checks them
    against NumPy).

    Args:
        pick: ``(K,) int64`` candidate point indices; size: the sample's size;
        iterations: hypotheses; seed: the generator's seed.

    Returns:
        ``(pick, tri)``: ``(min(K, size),) int64`` sampled indices and
        ``(iterations, 3) int64`` positions in them."""
    k = len(pick)
    if 10000 < k and k // 50 < size < k:
        # each pick and each triplet index takes one 32-bit half (rejections are ~1e-5)
        count = (size + 3 * iterations) // 2 + 64
        words = (_raw_words(int(seed), count) if isinstance(seed, int | np.integer) else
                 np.random.default_rng(seed).bit_generator.random_raw(count))
        sub, tri, ok = _tail_sample(words, k, size, 3 * iterations)
        if ok:
            return pick[sub], tri.reshape(iterations, 3)
    rng = np.random.default_rng(seed)
    if k > size:
        pick = pick[rng.choice(k, size, replace=False)]
    return pick, rng.integers(0, len(pick), size=(iterations, 3))


@functools.lru_cache(maxsize=8)
def _raw_words(seed: int, count: int) -> np.ndarray:
    """``(count,) uint64``: the first raw words of ``default_rng(seed)``, a function of the
    seed alone, so made once and not for every scan (a generator's construction is
    ~30 us, the road's longest NumPy call); read-only."""
    words = np.random.default_rng(seed).bit_generator.random_raw(count)
    words.flags.writeable = False
    return words


@numba.njit(cache=True)
def _tail_sample(words, k, size, n_tri):  # pragma: no cover - numba
    """NumPy's ``choice(k, size, replace=False)`` by tail shuffle, then
    ``integers(0, size, n_tri)``, on the raw 64-bit ``words`` of a fresh generator
    (its 32-bit stream: the low half of a word, then the high half). Returns
    ``(sub, tri, ok)``; ``ok`` is False if the words ran out."""
    data = np.arange(k, dtype=np.int32)  # half the memory of int64: its cost is touching it
    state = np.zeros(3, np.uint64)  # next word, a half pending, that half
    for i in range(k - 1, k - size - 1, -1):  # NumPy's _shuffle_int
        j = _lemire(words, state, np.uint64(i))
        t = data[j]
        data[j] = data[i]
        data[i] = t
    tri = np.empty(n_tri, np.int64)
    for i in range(n_tri):
        tri[i] = _lemire(words, state, np.uint64(size - 1))
    return data[k - size:].astype(np.int64), tri, state[0] <= words.shape[0]


@numba.njit(cache=True, inline="always")
def _lemire(words, state, rng):  # pragma: no cover - numba
    """NumPy's buffered_bounded_lemire_uint32: a draw in ``[0, rng]``."""
    excl = rng + np.uint64(1)
    m = _next_u32(words, state) * excl
    left = m & np.uint64(0xFFFFFFFF)
    if left < excl:
        threshold = (np.uint64(0xFFFFFFFF) - rng) % excl
        while left < threshold and state[0] <= words.shape[0]:  # (no words: give up)
            m = _next_u32(words, state) * excl
            left = m & np.uint64(0xFFFFFFFF)
    return m >> np.uint64(32)


@numba.njit(cache=True, inline="always")
def _next_u32(words, state):  # pragma: no cover - numba
    """The generator's next_uint32 on ``words``; past their end, 0 (and the count says so)."""
    if state[1]:
        state[1] = 0
        return state[2]
    if state[0] >= words.shape[0]:
        state[0] = words.shape[0] + 1
        return np.uint64(0)
    w = words[state[0]]
    state[0] += 1
    state[1] = 1
    state[2] = w >> np.uint64(32)
    return w & np.uint64(0xFFFFFFFF)


_BLOCK = 256  # candidates scored between two checks of a RANSAC hypothesis


@numba.njit(cache=True)
def best_plane(xyz, pick, tri, min_cos, dist):  # pragma: no cover - numba
    """The hypotheses of the fit: ``(cand, best, plane)``, the ``(K, 3)`` candidate
    rows ``xyz[pick]``, the index of the best plane through the triplets ``tri (I, 3)``
    of candidates (most candidates within ``dist``; of equal ones the first; -1 if no
    plane is within the tilt, ``normal_z >= min_cos``) and that plane ``(4,)``, unit
    normal up. One kernel: NumPy's fancy indexing of a column-major array and its small
    per-batch calls cost more than the scoring. A hypothesis is dropped once even its
    remaining candidates could not lift it above the best so far (it could not
    replace it: the same result as scoring it in full)."""
    k = pick.shape[0]
    cand = np.empty((k, 3))
    columns = np.empty((3, k))  # x, y, z rows: the scoring loop vectorises
    for q in range(k):
        for i in range(3):
            v = xyz[pick[q], i]
            cand[q, i] = v
            columns[i, q] = v
    x, y, z = columns[0], columns[1], columns[2]
    best = -1
    top = -1
    plane = np.zeros(4)
    for h in range(tri.shape[0]):
        p0, p1, p2 = cand[tri[h, 0]], cand[tri[h, 1]], cand[tri[h, 2]]
        a0, a1, a2 = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
        b0, b1, b2 = p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]
        n0 = a1 * b2 - a2 * b1  # the cross product, as np.cross
        n1 = a2 * b0 - a0 * b2
        n2 = a0 * b1 - a1 * b0
        norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if not norm > 1e-9:
            continue
        n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
        if n2 < 0:  # point up
            n0, n1, n2 = -n0, -n1, -n2
        if not n2 >= min_cos:
            continue
        e = -(n0 * p0[0] + n1 * p0[1] + n2 * p0[2])
        count = 0
        for q0 in range(0, k, _BLOCK):  # blocks that vectorise; a plane that cannot
            for q in range(q0, min(q0 + _BLOCK, k)):  # beat the best any more is dropped
                count += abs(n0 * x[q] + n1 * y[q] + n2 * z[q] + e) < dist
            if count + k - q0 - _BLOCK <= top:
                break
        if count > top:
            top = count
            best = h
            plane[0], plane[1], plane[2], plane[3] = n0, n1, n2, e
    return cand, best, plane


@numba.njit(cache=True)
def inlier_moments(cand, plane, dist):  # pragma: no cover - numba
    """Count, centre ``(3,)`` and scatter matrix ``(3, 3)`` of the plane's inliers."""
    n = 0
    s = np.zeros(3)
    for p in range(cand.shape[0]):
        d = plane[0] * cand[p, 0] + plane[1] * cand[p, 1] + plane[2] * cand[p, 2] + plane[3]
        if abs(d) < dist:
            n += 1
            for i in range(3):  # scalar sums: no temporary array per point
                s[i] += cand[p, i]
    centre = s / max(n, 1)
    m = np.zeros((3, 3))
    for p in range(cand.shape[0]):
        d = plane[0] * cand[p, 0] + plane[1] * cand[p, 1] + plane[2] * cand[p, 2] + plane[3]
        if abs(d) < dist:
            q0 = cand[p, 0] - centre[0]
            q1 = cand[p, 1] - centre[1]
            q2 = cand[p, 2] - centre[2]
            m[0, 0] += q0 * q0
            m[0, 1] += q0 * q1
            m[0, 2] += q0 * q2
            m[1, 0] += q1 * q0
            m[1, 1] += q1 * q1
            m[1, 2] += q1 * q2
            m[2, 0] += q2 * q0
            m[2, 1] += q2 * q1
            m[2, 2] += q2 * q2
    return n, centre, m


@numba.njit(cache=True)
def refit(cand, plane, dist, rounds):  # pragma: no cover - numba
    """``(4,)`` the plane refit ``rounds`` times by least squares to the candidates
    ``cand (K, 3)`` within ``dist`` of it: the normal is the eigenvector of the smallest
    eigenvalue of their scatter matrix (``np.linalg.eigh``), turned up; stops early when
    fewer than 3 are left. One call (was ~0.15 ms of NumPy calls; the same planes on
    the 40 KITTI scans and the bench sweeps)."""
    plane = plane.copy()
    for _ in range(rounds):
        count, centre, scatter = inlier_moments(cand, plane, dist)
        if count < 3:
            break
        n = np.ascontiguousarray(np.linalg.eigh(scatter)[1][:, 0])
        if not n[2] > 0:
            n = -n
        plane[0], plane[1], plane[2] = n[0], n[1], n[2]
        plane[3] = -np.dot(n, centre)
    return plane
