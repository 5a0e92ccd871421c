"""Street graph -> lanes: one routine shared by the city generator and the OSM loader."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dstenv.sim.lanes import (LaneKind, NetworkBuilder, Turn, bezier, cut_polyline, fillet_curve,
                              offset_polyline)
from dstenv.sim.roundabout import add_ring

__all__ = ["RoadEdge", "add_road_lanes", "signal_group", "balloon", "turning_circle"]

STRAIGHT_ANGLE = np.deg2rad(35.0)  # [rad] heading change below which a manoeuvre is straight
UTURN_RADIUS = 4.5  # [m] loop radius of a U-turn at a dead end (a car can follow it)
UTURN_AHEAD = 4.0  # [m] from the lane ends to the near edge of the U-turn loop (smooth legs)


@dataclass
class RoadEdge:
    """A street between two nodes of the street graph.

    Attributes:
        u, v: node ids at the start and end of ``poly``.
        poly: ``(K, 2) float64`` centre-line from node ``u`` to node ``v`` [m].
        n_fwd: lanes in the direction u -> v (>= 1).
        n_bwd: lanes in the direction v -> u (0: one-way street).
        lane_width: lane width of this street [m] (None: the network's).
        median: width of a raised median between the two directions [m] (0: none).
    """

    u: int
    v: int
    poly: np.ndarray
    n_fwd: int
    n_bwd: int
    lane_width: float | None = None
    median: float = 0.0


def signal_group(heading: float) -> int:
    """Traffic-light phase (0 or 1) of an approach: axis of its heading."""
    return int(((heading % np.pi) + np.pi / 4) // (np.pi / 2)) % 2


def balloon(p0: np.ndarray, h0: float, p1: np.ndarray, radius: float = UTURN_RADIUS) -> np.ndarray:
    """U-turn at a dead end: a counter-clockwise loop of ``radius`` [m] around a point
    ahead of the lane ends (a turning circle), from ``p0`` (heading ``h0``) to ``p1``."""
    d = np.array([np.cos(h0), np.sin(h0)])
    left = np.array([-d[1], d[0]])
    mid = (np.asarray(p0) + np.asarray(p1)) / 2
    centre = mid + d * (UTURN_AHEAD + 0.5 * radius)
    ang = np.deg2rad(np.linspace(-110.0, 110.0, 23))
    ring = centre + radius * (np.cos(ang)[:, None] * d + np.sin(ang)[:, None] * left)
    return np.vstack([p0, ring, p1])


def turning_circle(node_xy: np.ndarray, h_in: float, uturn_trim: float,
                   radius: float = UTURN_RADIUS) -> tuple[np.ndarray, float]:
    """Centre and radius [m] of the paved disc a :func:`balloon` U-turn needs at a dead
    end reached at heading ``h_in`` (a car's half width and a margin included)."""
    d = np.array([np.cos(h_in), np.sin(h_in)])
    centre = np.asarray(node_xy) + d * (UTURN_AHEAD - uturn_trim + 0.5 * radius)
    return centre, radius + 2.4


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


def add_road_lanes(builder: NetworkBuilder, n_nodes: int, edges: list[RoadEdge],
                   trims: np.ndarray, lane_width: float, uturn_trim: float = 3.0,
                   kerb_radius: float = 4.375, roundabouts: list | None = None) -> np.ndarray:
    """Add the road and connector lanes of a street graph to ``builder``.

    Lanes keep to the right. Road lanes stop ``trims[node]`` metres before each
    junction (the stop line); connectors join them through the junction: straight
    on from every lane, left turns from the innermost lane, right turns from the
    kerb lane, U-turns only at dead ends.

    Args:
        builder: collects the lanes.
        n_nodes: number of street-graph nodes.
        edges: the streets.
        trims: ``(n_nodes,) float64`` stop-line distance from each node [m].
        lane_width: [m].
        uturn_trim: stop-line distance at dead ends [m].
        kerb_radius: radius [m] of the painted kerb corner that right turns go round
            (the default puts a 3.25 m kerb lane on a 6 m turn). A right turn is an arc
            concentric with it (the corners square): straight - arc of radius
            ``kerb_radius + max(da, db)`` - straight, ``da`` / ``db`` the distances of
            its two lanes' centres from their kerbs, so it stays ``min(da, db)`` from
            the kerb all the way round, as a car that keeps to its lane does; other
            manoeuvres are smooth cubic curves.
        roundabouts: :class:`~dstenv.sim.roundabout.Roundabout` s replacing the
            connectors of their nodes by a one-way ring.

    Returns:
        ``(n_nodes,) int64`` node degrees (streets meeting at each node).
    """
    degree = np.zeros(n_nodes, np.int64)
    for e in edges:
        degree[e.u] += 1
        degree[e.v] += 1
    inc: list[list[tuple]] = [[] for _ in range(n_nodes)]
    out: list[list[tuple]] = [[] for _ in range(n_nodes)]
    for ei, e in enumerate(edges):
        poly = np.asarray(e.poly, np.float64)
        total = float(np.hypot(*np.diff(poly, axis=0).T).sum())
        t_u = uturn_trim if degree[e.u] == 1 else float(trims[e.u])
        t_v = uturn_trim if degree[e.v] == 1 else float(trims[e.v])
        if total - t_u - t_v < 2.0:  # short street: keep at least 2 m (or 40 %) of lane
            keep = min(2.0, 0.4 * total)
            scale = (total - keep) / max(t_u + t_v, 1e-9)
            t_u, t_v = t_u * scale, t_v * scale
        centre = cut_polyline(poly, t_u, total - t_v)
        for direction, n, line, a, b in ((0, e.n_fwd, centre, e.u, e.v),
                                         (1, e.n_bwd, centre[::-1], e.v, e.u)):
            lw = e.lane_width or lane_width
            for k in range(n):
                off = -(k + 0.5) * lw - e.median / 2 if e.n_bwd > 0 else \
                    -(k - (n - 1) / 2) * lw
                lane_poly = offset_polyline(line, off)
                lid = builder.add(lane_poly, LaneKind.ROAD, rightmost=(k == n - 1))
                d0, d1 = lane_poly[1] - lane_poly[0], lane_poly[-1] - lane_poly[-2]
                out[a].append((lid, ei, k, n, float(np.arctan2(d0[1], d0[0])), lane_poly[0]))
                inc[b].append((lid, ei, k, n, float(np.arctan2(d1[1], d1[0])), lane_poly[-1]))
    lws = [e.lane_width or lane_width for e in edges]
    rings = {r.node: r for r in roundabouts or []}
    for node in range(n_nodes):
        if node in rings:
            add_ring(builder, rings[node], inc[node], out[node])
            continue
        by_edge: dict[int, list[tuple]] = {}
        for o in out[node]:
            by_edge.setdefault(o[1], []).append(o)
        for a, ea, ka, na, ha, pa in inc[node]:
            made = _connect(builder, node, degree[node], by_edge, a, ea, ka, na, ha, pa, False,
                            kerb_radius, lws)
            if not made:  # e.g. a middle lane at a T: let it turn anyway
                _connect(builder, node, degree[node], by_edge, a, ea, ka, na, ha, pa, True,
                         kerb_radius, lws)
    return degree


def _connect(builder: NetworkBuilder, node: int, deg: int, by_edge: dict, a: int, ea: int,
             ka: int, na: int, ha: float, pa: np.ndarray, relaxed: bool,
             kerb_radius: float, lws: list[float]) -> bool:
    made = False
    for eb, outs in by_edge.items():
        if eb == ea and deg > 1:
            continue
        hb = outs[0][4]
        theta = _wrap(hb - ha)
        if eb == ea:
            turn = Turn.UTURN
        elif abs(theta) < STRAIGHT_ANGLE:
            turn = Turn.STRAIGHT
        else:
            turn = Turn.LEFT if theta > 0 else Turn.RIGHT
        nb_ = outs[0][3]
        if relaxed or deg <= 2 or turn == Turn.STRAIGHT:
            k_out = min(ka, nb_ - 1)
        elif turn in (Turn.LEFT, Turn.UTURN):
            if ka != 0:
                continue
            k_out = 0
        else:
            if ka != na - 1:
                continue
            k_out = nb_ - 1
        b, _, _, _, hb, pb = next(o for o in outs if o[2] == k_out)
        if np.hypot(pb[0] - pa[0], pb[1] - pa[1]) < 1e-6:
            continue
        poly = None
        if turn == Turn.RIGHT:  # round the kerb corner, each lane as far from it as before
            gap = max(_kerb_gap(ka, na, lws[ea]), _kerb_gap(k_out, nb_, lws[eb]))
            poly = fillet_curve(pa, ha, pb, hb, kerb_radius + gap)
        if turn == Turn.UTURN:
            poly = balloon(pa, ha, pb)
        if poly is None:
            poly = bezier(pa, ha, pb, hb, n=24, k=0.42)
        c = builder.add(poly, LaneKind.CONNECTOR, node=node, turn=turn, group=signal_group(ha))
        builder.link(a, c)
        builder.link(c, b)
        made = True
    return made


def _kerb_gap(k: int, n: int, lw: float) -> float:
    """Distance [m] from the right kerb to the centre of lane ``k`` of ``n`` (``k = 0``
    innermost; the lanes of a direction fill the carriageway from the kerb)."""
    return (n - k - 0.5) * lw
