"""The lane network: centre-lines with direction, successors and junction conflicts.

Every path an agent follows is a *lane*: a directed centre-line resampled at an
even spacing (<= 0.5 m). Road lanes run between junctions; connector lanes lead
through a junction from an incoming lane to an outgoing one; sidewalk and crossing
lanes carry pedestrians. ``WorldMap.lanes`` holds a :class:`LaneNetwork`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from enum import IntEnum

import numba as nb
import numpy as np

# the polyline kernels live in lanegeom; re-exported here, where lanes are built
from dstenv.sim.lanegeom import (SPACING, bezier, cut_polyline, fillet_curve,  # noqa: F401
                                 offset_polyline, resample, resample_each)

__all__ = ["LaneKind", "Control", "Turn", "LaneNetwork", "NetworkBuilder", "lane_pose",
           "project_on_lane", "resample", "offset_polyline", "cut_polyline", "bezier",
           "fillet_curve"]

CONFLICT_DIST = 2.6  # [m] connectors closer than this somewhere conflict
LATERAL_ACCEL = 2.5  # [m/s^2] comfortable lateral acceleration in turns


class LaneKind(IntEnum):
    """What moves on a lane."""

    ROAD = 0  # vehicles, between junctions
    CONNECTOR = 1  # vehicles, through a junction
    SIDEWALK = 2  # pedestrians
    CROSSING = 3  # pedestrians, across a road


class Control(IntEnum):
    """Right-of-way rule of a junction."""

    NONE = 0  # no junction (bend, dead end): no request needed
    YIELD = 1  # first come, first served
    STOP = 2  # all-way stop: stand still before requesting
    SIGNAL = 3  # fixed-time traffic lights, two phases


class Turn(IntEnum):
    """Manoeuvre of a connector."""

    STRAIGHT = 0
    LEFT = 1
    RIGHT = 2
    UTURN = 3


@dataclass
class LaneNetwork:
    """All lanes of a map as flat arrays (numba friendly).

    Attributes:
        pts: ``(P, 2) float64`` resampled points of all lanes, lane after lane.
        hdg: ``(P,) float64`` heading [rad] of the segment leaving each point.
        start, npts: ``(L,) int64`` first point and point count of each lane.
        length, ds: ``(L,) float64`` lane length and point spacing [m].
        kind: ``(L,) uint8`` :class:`LaneKind`.
        node: ``(L,) int64`` junction of a connector (-1 for other lanes).
        turn: ``(L,) uint8`` :class:`Turn` of a connector.
        group: ``(L,) uint8`` signal phase (0/1) of a connector.
        rightmost: ``(L,) bool`` road lane next to the kerb.
        vmax: ``(L,) float64`` curvature speed limit [m/s].
        succ_ptr, succ: successors of lane ``l`` are ``succ[succ_ptr[l]:succ_ptr[l+1]]``.
        conf_ptr, conf: connectors conflicting with connector ``l`` (same CSR layout).
        node_xy: ``(J, 2) float64`` junction positions; node_control ``(J,) uint8``
            :class:`Control`; node_phase ``(J,) float64`` signal offset [s].
        lane_width: [m].
    """

    pts: np.ndarray
    hdg: np.ndarray
    start: np.ndarray
    npts: np.ndarray
    length: np.ndarray
    ds: np.ndarray
    kind: np.ndarray
    node: np.ndarray
    turn: np.ndarray
    group: np.ndarray
    rightmost: np.ndarray
    vmax: np.ndarray
    succ_ptr: np.ndarray
    succ: np.ndarray
    conf_ptr: np.ndarray
    conf: np.ndarray
    node_xy: np.ndarray
    node_control: np.ndarray
    node_phase: np.ndarray
    lane_width: float = 3.25

    def __len__(self) -> int:
        return int(self.start.shape[0])

    @cached_property
    def heading_trig(self) -> tuple[np.ndarray, np.ndarray]:
        """``(cos, sin)`` of :attr:`hdg`, ``(P,) float64`` each (:func:`heading_trig`),
        computed at the first read and kept with the network (a pool map keeps them)."""
        return heading_trig(self.hdg)

    def polyline(self, lane: int) -> np.ndarray:
        """Points of one lane: ``(K, 2) float64``."""
        return self.pts[self.start[lane]:self.start[lane] + self.npts[lane]]

    def successors(self, lane: int) -> np.ndarray:
        """Lanes that may follow ``lane``: ``(S,) int64``."""
        return self.succ[self.succ_ptr[lane]:self.succ_ptr[lane + 1]]

    def pose(self, lane: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World position and heading at arc length ``s`` on ``lane``.

        Args:
            lane: ``(N,) int64`` lane ids; s: ``(N,) float64`` [m].

        Returns:
            ``xy (N, 2) float64`` [m] and ``yaw (N,) float64`` [rad].
        """
        lane, s = np.atleast_1d(lane), np.atleast_1d(s)
        xy = np.empty((len(lane), 2))
        yaw = np.empty(len(lane))
        for i in range(len(lane)):
            xy[i, 0], xy[i, 1], yaw[i] = lane_pose(self.pts, self.hdg, self.start, self.npts,
                                                   self.ds, int(lane[i]), float(s[i]))
        return xy, yaw


@nb.njit(cache=True)
def heading_trig(hdg):  # pragma: no cover - numba
    """``(cos, sin)`` of the lane headings, ``(P,) float64`` each, computed once per
    network for the traffic's look-ahead paths (numba's scalar cos/sin, so the values
    are bit-identical to evaluating them in a kernel)."""
    c, s = np.empty_like(hdg), np.empty_like(hdg)
    for p in range(hdg.shape[0]):
        c[p], s[p] = np.cos(hdg[p]), np.sin(hdg[p])
    return c, s


@nb.njit(cache=True)
def lane_pose(pts, hdg, start, npts, ds, lane, s):
    """``(x, y, yaw)`` at arc length ``s`` on ``lane`` (clamped to the lane)."""
    f = s / ds[lane]
    i = int(np.floor(f))
    if i < 0:
        i, f = 0, 0.0
    if i > npts[lane] - 2:
        i = npts[lane] - 2
        f = float(npts[lane] - 1)
    t = f - i
    p = start[lane] + i
    x = pts[p, 0] + t * (pts[p + 1, 0] - pts[p, 0])
    y = pts[p, 1] + t * (pts[p + 1, 1] - pts[p, 1])
    return x, y, hdg[p]


@nb.njit(cache=True)
def project_on_lane(pts, start, npts, ds, lane, x, y, s_guess, window):
    """Closest point of ``lane`` to ``(x, y)`` within ``s_guess +- window`` [m].

    Returns ``(s, lateral, dist)``: arc length, signed offset (left +) and distance.
    """
    n = npts[lane]
    lo = max(int((s_guess - window) / ds[lane]) - 1, 0)
    hi = min(int((s_guess + window) / ds[lane]) + 1, n - 2)
    best, bs, blat = 1e18, 0.0, 0.0
    for i in range(lo, hi + 1):
        p = start[lane] + i
        ax, ay = pts[p, 0], pts[p, 1]
        dx, dy = pts[p + 1, 0] - ax, pts[p + 1, 1] - ay
        seg2 = dx * dx + dy * dy
        t = ((x - ax) * dx + (y - ay) * dy) / seg2 if seg2 > 0 else 0.0
        t = min(max(t, 0.0), 1.0)
        qx, qy = ax + t * dx - x, ay + t * dy - y
        d2 = qx * qx + qy * qy
        if d2 < best:
            best, bs = d2, (i + t) * ds[lane]
            blat = (dx * (y - ay) - dy * (x - ax)) / np.sqrt(max(seg2, 1e-18))
    return bs, blat, np.sqrt(best)


class NetworkBuilder:
    """Collects lane polylines and links, then packs them into a :class:`LaneNetwork`."""

    def __init__(self) -> None:
        self._polys: list[np.ndarray] = []  # resampled lanes
        self._raw: list[np.ndarray] = []  # lanes added since, resampled at the next read
        self.attrs: list[tuple[int, int, int, int, bool]] = []  # kind, node, turn, group, right
        self.links: list[list[int]] = []

    @property
    def polys(self) -> list[np.ndarray]:
        """The lanes' points, each ``(M, 2) float64`` resampled to :data:`SPACING`
        (:func:`~dstenv.sim.lanegeom.resample`; lanes added since the last read are
        resampled together, one kernel call instead of one per lane)."""
        if self._raw:
            raw, self._raw = self._raw, []
            ptr = np.cumsum([0] + [len(p) for p in raw]).astype(np.int64)
            out, bad = resample_each(np.concatenate(raw), ptr)
            if bad >= 0:
                raise ValueError(f"lane {len(self._polys) + bad}: lane polyline needs two "
                                 "distinct points")
            self._polys.extend(out)
        return self._polys

    @polys.setter
    def polys(self, polys: list[np.ndarray]) -> None:
        self._raw, self._polys = [], list(polys)

    def add(self, poly: np.ndarray, kind: LaneKind, node: int = -1, turn: Turn = Turn.STRAIGHT,
            group: int = 0, rightmost: bool = False) -> int:
        """Add a lane (points in driving order) and return its id (a lane without two
        distinct points raises ValueError at the next read of :attr:`polys`)."""
        self._raw.append(np.asarray(poly, np.float64).reshape(-1, 2))
        self.attrs.append((int(kind), int(node), int(turn), int(group), bool(rightmost)))
        self.links.append([])
        return len(self.attrs) - 1

    def link(self, a: int, b: int) -> None:
        """Allow lane ``b`` to follow lane ``a``."""
        if b not in self.links[a]:
            self.links[a].append(b)

    def build(self, node_xy: np.ndarray, node_control: np.ndarray, node_phase: np.ndarray,
              lane_width: float) -> LaneNetwork:
        """Pack the lanes; computes headings, curvature limits and connector conflicts
        (an uncontrolled node whose connectors conflict becomes a yield junction)."""
        npts = np.array([len(p) for p in self.polys], np.int64)
        if not len(npts) or npts.min() < 2:  # the compiled kernels assume both
            raise ValueError("lane network: needs lanes of at least two points each")
        start = np.concatenate([[0], np.cumsum(npts)[:-1]]).astype(np.int64)
        pts = np.concatenate(self.polys) if self.polys else np.zeros((0, 2))
        # segment headings and lengths of all lanes at once (a lane's last point keeps
        # its last segment's heading; the segments across lane ends are not used)
        d_all = np.diff(pts, axis=0)
        h_all = np.arctan2(d_all[:, 1], d_all[:, 0])
        seg_all = np.hypot(d_all[:, 0], d_all[:, 1])
        hdg = np.append(h_all, 0.0) if len(pts) else np.zeros(0)
        if len(npts):
            hdg[start + npts - 1] = hdg[start + npts - 2]
        attrs = np.array(self.attrs, dtype=np.int64).reshape(-1, 5)
        length, vmax = _lane_stats(seg_all, h_all, start, npts, attrs[:, 0] == LaneKind.CONNECTOR)
        succ_ptr = np.cumsum([0] + [len(s) for s in self.links]).astype(np.int64)
        succ = np.array([b for s in self.links for b in s], np.int64)
        conflicts = self._conflicts(attrs, succ_ptr, succ)
        conf_ptr = np.cumsum([0] + [len(c) for c in conflicts]).astype(np.int64)
        conf = np.array([b for c in conflicts for b in c], np.int64)
        # a node whose paths merge or cross needs a right-of-way rule: an uncontrolled
        # one (a bend where two lanes become one) gives way first come, first served
        node_control = np.array(node_control, np.uint8)
        for c, others in enumerate(conflicts):
            if others and 0 <= attrs[c, 1] < len(node_control) \
                    and node_control[attrs[c, 1]] == Control.NONE:
                node_control[attrs[c, 1]] = Control.YIELD
        return LaneNetwork(
            pts=pts, hdg=hdg, start=start, npts=npts, length=length,
            ds=length / np.maximum(npts - 1, 1), kind=attrs[:, 0].astype(np.uint8),
            node=attrs[:, 1].copy(), turn=attrs[:, 2].astype(np.uint8),
            group=attrs[:, 3].astype(np.uint8), rightmost=attrs[:, 4].astype(bool), vmax=vmax,
            succ_ptr=succ_ptr, succ=succ, conf_ptr=conf_ptr, conf=conf,
            node_xy=np.asarray(node_xy, np.float64).reshape(-1, 2),
            node_control=np.asarray(node_control, np.uint8),
            node_phase=np.asarray(node_phase, np.float64), lane_width=float(lane_width))

    def _conflicts(self, attrs: np.ndarray, succ_ptr: np.ndarray, succ: np.ndarray
                   ) -> list[list[int]]:
        """Conflicting connectors of each lane (in the order of the pairs ``a < b`` of
        each junction): not from a common lane, and merging into a common lane or
        closer than :data:`CONFLICT_DIST` somewhere."""
        out: list[list[int]] = [[] for _ in self.polys]
        # predecessors in CSR form (the order within a lane does not matter)
        src = np.repeat(np.arange(len(self.links), dtype=np.int64), np.diff(succ_ptr))
        order = np.argsort(succ, kind="stable")
        pred, pred_ptr = src[order], np.searchsorted(succ[order], np.arange(len(self.links) + 1))
        conn = np.flatnonzero(attrs[:, 0] == LaneKind.CONNECTOR) if len(attrs) else []
        by_node: dict[int, list[int]] = {}
        for c in conn:
            by_node.setdefault(int(attrs[c, 1]), []).append(int(c))
        for members in by_node.values():
            pts = [self.polys[m][::2] for m in members]
            ptr = np.cumsum([0] + [len(q) for q in pts]).astype(np.int64)
            d2 = _pair_dist2(np.concatenate(pts), ptr)  # (M, M) least squared distances
            ia, ib = np.nonzero(_conflict_pairs(np.array(members, np.int64), d2, pred_ptr,
                                                pred, succ_ptr, succ, CONFLICT_DIST ** 2))
            for x, y in zip(ia.tolist(), ib.tolist()):
                out[members[x]].append(members[y])
                out[members[y]].append(members[x])
        return out


@nb.njit(cache=True)
def _share(ptr, vals, a, b):  # pragma: no cover - numba
    """Lanes ``a`` and ``b`` have a common entry in the CSR lists ``vals[ptr[l]:ptr[l+1]]``."""
    for i in range(ptr[a], ptr[a + 1]):
        for j in range(ptr[b], ptr[b + 1]):
            if vals[i] == vals[j]:
                return True
    return False


@nb.njit(cache=True)
def _conflict_pairs(members, d2, pred_ptr, pred, succ_ptr, succ, dist2):  # pragma: no cover
    """``(M, M) bool`` upper triangle: connectors ``members[i] < members[j]`` of one
    junction conflict. From the same lane: one behind the other, car following keeps
    them apart; into the same lane: they merge, so they conflict."""
    m = members.shape[0]
    out = np.zeros((m, m), np.bool_)
    for ia in range(m):
        for ib in range(ia + 1, m):
            a, b = members[ia], members[ib]
            if _share(pred_ptr, pred, a, b):
                continue
            out[ia, ib] = _share(succ_ptr, succ, a, b) or d2[ia, ib] < dist2
    return out


@nb.njit(cache=True)
def _pair_dist2(pts, ptr):  # pragma: no cover - numba
    """``(M, M)`` least squared distance between the point sets ``pts[ptr[i]:ptr[i+1]]``
    (``pts (P, 2)``) of every pair ``i < j`` (upper triangle; the rest is inf)."""
    m = ptr.shape[0] - 1
    out = np.full((m, m), np.inf)
    for a in range(m):
        for b in range(a + 1, m):
            best = np.inf
            for i in range(ptr[a], ptr[a + 1]):
                for j in range(ptr[b], ptr[b + 1]):
                    dx, dy = pts[i, 0] - pts[j, 0], pts[i, 1] - pts[j, 1]
                    best = min(best, dx * dx + dy * dy)
            out[a, b] = best
    return out


@nb.njit(cache=True)
def _pairwise_sum(a, lo, n):  # pragma: no cover - numba
    """``a[lo:lo + n].sum()`` as numpy adds (pairwise, 8 accumulators, blocks of 128):
    the same bits as the numpy expression it replaces."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    if n <= 128:
        r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
        r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
        i = 8
        while i < n - (n % 8):
            r0 += a[lo + i]
            r1 += a[lo + i + 1]
            r2 += a[lo + i + 2]
            r3 += a[lo + i + 3]
            r4 += a[lo + i + 4]
            r5 += a[lo + i + 5]
            r6 += a[lo + i + 6]
            r7 += a[lo + i + 7]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < n:
            res += a[lo + i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise_sum(a, lo, n2) + _pairwise_sum(a, lo + n2, n - n2)


@nb.njit(cache=True)
def _lane_stats(seg, h, start, npts, connector):  # pragma: no cover - numba
    """Length ``(L,)`` [m] and curvature speed limit ``(L,)`` [m/s] of every lane from
    the segment lengths ``seg`` and headings ``h`` of all points: a connector's
    curvature is its largest heading change over 4 segments (~2 m)."""
    n_l = start.shape[0]
    length = np.zeros(n_l)
    vmax = np.full(n_l, 30.0)
    for i in range(n_l):
        a, n = start[i], npts[i] - 1
        length[i] = 0.0 + _pairwise_sum(seg, a, n)
        if connector[i] and n > 4:
            dh = 0.0
            for j in range(a, a + n - 4):
                x = h[j + 4] - h[j]
                dh = max(dh, abs(np.arctan2(np.sin(x), np.cos(x))))  # |np.angle(e^ix)|
            kappa = dh / (4 * length[i] / n)
            vmax[i] = min(30.0, np.sqrt(LATERAL_ACCEL / max(kappa, 1e-6)))
    return length, vmax
