"""Pedestrian lanes of the procedural city: rings around blocks and crosswalks.

Every block has two sidewalk rings: the outer one (nearer the kerb) walked
counter-clockwise, the inner one clockwise, so pedestrians never meet head-on.
Crosswalks join the outer rings of neighbouring blocks just outside a junction;
the two walking directions of a crosswalk use separate lines 1.2 m apart.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from dstenv.sim.lanegeom import interp_row
from dstenv.sim.lanes import LaneKind, NetworkBuilder

__all__ = ["rounded_rect", "add_block_rings"]

LANE_OFFSET = 0.6  # [m] half the distance between the two walking lines of a sidewalk
CORNER_RADIUS = 1.0  # [m] rounding of a ring's corners
_QUARTER = np.linspace(0, np.pi / 2, 5)  # corner arc angles [rad]
_QUARTER.flags.writeable = False


def rounded_rect(x0: float, x1: float, y0: float, y1: float,
                 r: float = CORNER_RADIUS) -> np.ndarray:
    """Closed counter-clockwise ring around a box with rounded corners: ``(21, 2)
    float64`` (four quarter arcs of 5 points, the first point repeated at the end)."""
    return _rounded_rect(float(x0), float(x1), float(y0), float(y1),
                         min(r, (x1 - x0) / 3, (y1 - y0) / 3), _QUARTER)


@nb.njit(cache=True)
def _rounded_rect(x0, x1, y0, y1, r, quarter):  # pragma: no cover - numba
    q = quarter.shape[0]
    out = np.empty((4 * q + 1, 2))
    corners = ((x1 - r, y0 + r, -np.pi / 2), (x1 - r, y1 - r, 0.0),
               (x0 + r, y1 - r, np.pi / 2), (x0 + r, y0 + r, np.pi))
    for k in range(4):
        cx, cy, a0 = corners[k]
        for j in range(q):
            out[k * q + j, 0] = cx + r * np.cos(a0 + quarter[j])
            out[k * q + j, 1] = cy + r * np.sin(a0 + quarter[j])
    out[4 * q] = out[0]
    return out


def _arc(ring: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    """Arc length of the projection of ``p`` on a ring and the distance to it."""
    return _arc_nb(np.ascontiguousarray(ring, np.float64), float(p[0]), float(p[1]))


@nb.njit(cache=True)
def _arc_nb(ring, px, py):  # pragma: no cover - numba
    """:func:`_arc` in one pass: the nearest point over the segments (the first of
    equals), its arc length and distance."""
    best, s_best, cum = np.inf, 0.0, 0.0
    for i in range(ring.shape[0] - 1):
        dx, dy = ring[i + 1, 0] - ring[i, 0], ring[i + 1, 1] - ring[i, 1]
        seg = np.hypot(dx, dy)
        t = ((px - ring[i, 0]) * dx + (py - ring[i, 1]) * dy) / max(seg * seg, 1e-12)
        t = min(max(t, 0.0), 1.0)
        dist = np.hypot(ring[i, 0] + t * dx - px, ring[i, 1] + t * dy - py)
        if dist < best:
            best, s_best = dist, cum + t * seg
        cum += seg
    return s_best, best


def _split(ring: np.ndarray, cuts: list[float]) -> list[np.ndarray]:
    """Pieces of a closed ring ``(K, 2)`` between consecutive arc lengths ``cuts``
    (sorted; the last piece wraps past the ring's start): ``(M_i, 2) float64`` each."""
    pts, ptr = _split_nb(np.ascontiguousarray(ring, np.float64), np.asarray(cuts, np.float64))
    return [pts[ptr[i]:ptr[i + 1]] for i in range(len(cuts))]


@nb.njit(cache=True)
def _split_nb(ring, cuts):  # pragma: no cover - numba
    """:func:`_split` as one array ``(P, 2)`` and offsets ``(len(cuts) + 1,)``; each
    piece is its two cut points and the ring's points strictly between, interpolated
    on the cumulative arc length as ``np.interp`` does (same bits as numpy)."""
    k, n = ring.shape[0], cuts.shape[0]
    cum = np.empty(k)
    cum[0] = 0.0
    for j in range(1, k):
        cum[j] = cum[j - 1] + np.hypot(ring[j, 0] - ring[j - 1, 0], ring[j, 1] - ring[j - 1, 1])
    total = cum[k - 1]
    out = np.empty((n * (2 * k + 2), 2))
    ptr = np.zeros(n + 1, np.int64)
    m = 0
    for i in range(n):
        s0 = cuts[i]
        s1 = cuts[i + 1] + 0.0 if i + 1 < n else cuts[0] + total
        interp_row(s0 - total if s0 > total else s0, cum, ring, out, m)
        m += 1
        for j in range(k):
            if s0 < cum[j] < s1:
                interp_row(cum[j], cum, ring, out, m)
                m += 1
        if s1 > total:  # the piece wraps past the ring's start
            for j in range(k):
                if cum[j] < s1 - total:
                    s = cum[j] + total
                    interp_row(s - total if s > total else s, cum, ring, out, m)
                    m += 1
        interp_row(s1 - total if s1 > total else s1, cum, ring, out, m)
        m += 1
        ptr[i + 1] = m
    return out[:m], ptr


def add_block_rings(builder: NetworkBuilder, faces: list[tuple[float, float, float, float]],
                    inset: float, crossings: list[tuple[int, int, np.ndarray, np.ndarray]],
                    offset: float = LANE_OFFSET) -> int:
    """Add sidewalk rings of all blocks and the crosswalks between them.

    Args:
        builder: collects the lanes.
        faces: block boxes ``(x0, x1, y0, y1)`` at the kerb [m].
        inset: distance from the kerb to the sidewalk's middle [m].
        crossings: ``(face_from, face_to, p_from, p_to)``: a crosswalk line from a point
            on the outer ring of one block to a point on the outer ring of another.

    Returns:
        Number of crosswalk lanes added (crossings whose ends miss a ring are dropped).
    """
    outer = [rounded_rect(x0 + inset - offset, x1 - inset + offset,
                          y0 + inset - offset, y1 - inset + offset)
             for x0, x1, y0, y1 in faces]
    cuts: list[list[tuple[float, int, str]]] = [[] for _ in faces]
    kept = []
    for ci, (fa, fb, pa, pb) in enumerate(crossings):
        sa, da = _arc(outer[fa], pa)
        sb, db = _arc(outer[fb], pb)
        if da > 0.05 or db > 0.05:
            continue
        cuts[fa].append((sa, ci, "dep"))
        cuts[fb].append((sb, ci, "arr"))
        kept.append(ci)
    cross_lane = {ci: builder.add(np.stack([crossings[ci][2], crossings[ci][3]]), LaneKind.CROSSING)
                  for ci in kept}
    for f, (x0, x1, y0, y1) in enumerate(faces):
        inner = rounded_rect(x0 + inset + offset, x1 - inset - offset,
                             y0 + inset + offset, y1 - inset - offset)[::-1]
        lid = builder.add(inner, LaneKind.SIDEWALK)
        builder.link(lid, lid)
        marks = sorted(c for c in cuts[f] if c[1] in cross_lane)
        if not marks:
            lid = builder.add(outer[f], LaneKind.SIDEWALK)
            builder.link(lid, lid)
            continue
        pieces = _split(outer[f], [m[0] for m in marks])
        ids = [builder.add(p, LaneKind.SIDEWALK) for p in pieces]
        for k, (_, ci, role) in enumerate(marks):
            before, after = ids[k - 1], ids[k]  # piece k starts at mark k
            builder.link(before, after)
            if role == "dep":
                builder.link(before, cross_lane[ci])
            else:
                builder.link(cross_lane[ci], after)
    return len(kept)
