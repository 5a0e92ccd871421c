"""Pedestrian lanes of the procedural city: rings around blocks and crosswalks.

Every block has two sidewalk rings: the outer one (nearer the kerb) walked
counter-clockwise, the inner one clockwise, so pedestrians never meet head-on.
Crosswalks join the outer rings of neighbouring blocks just outside a junction;
the two walking directions of a crosswalk use separate lines 1.2 m apart.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from dstenv.sim.lanes import LaneKind, NetworkBuilder

__all__ = ["rounded_rect", "add_block_rings"]

LANE_OFFSET = 0.6  # [m] half the distance between the two walking lines of a sidewalk
CORNER_RADIUS = 1.0  # [m] rounding of a ring's corners
_QUARTER = np.linspace(0, np.pi / 2, 5)  # corner arc angles [rad]
_QUARTER.flags.writeable = False


def rounded_rect(x0: float, x1: float, y0: float, y1: float,
                 r: float = CORNER_RADIUS) -> np.ndarray:
    """Closed counter-clockwise ring around a box with rounded corners: ``(K, 2)``."""
    r = min(r, (x1 - x0) / 3, (y1 - y0) / 3)
    a = _QUARTER
    pts = []
    for cx, cy, a0 in ((x1 - r, y0 + r, -np.pi / 2), (x1 - r, y1 - r, 0.0),
                       (x0 + r, y1 - r, np.pi / 2), (x0 + r, y0 + r, np.pi)):
        pts.append(np.stack([cx + r * np.cos(a0 + a), cy + r * np.sin(a0 + a)], -1))
    ring = np.concatenate(pts)
    return np.vstack([ring, ring[:1]])


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
    """Pieces of a closed ring between consecutive arc lengths ``cuts`` (sorted)."""
    seg = np.hypot(*np.diff(ring, axis=0).T)
    cum = np.concatenate([[0], np.cumsum(seg)])
    total = cum[-1]
    out = []
    for i, s0 in enumerate(cuts):
        s1 = cuts[(i + 1) % len(cuts)] + (total if i + 1 == len(cuts) else 0.0)
        s = np.concatenate([[s0], cum[(cum > s0) & (cum < s1)],
                            cum[cum < s1 - total] + total if s1 > total else [], [s1]])
        s = np.where(s > total, s - total, s)
        out.append(np.stack([np.interp(s, cum, ring[:, 0]), np.interp(s, cum, ring[:, 1])], -1))
    return out


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
