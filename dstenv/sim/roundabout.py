"""Roundabouts of the procedural city: a 4-way junction turned into a one-way ring.

Traffic keeps right, so the ring is driven counter-clockwise around a raised central
island (:attr:`MapClass.INTERMEDIATE`, ``non_navigable``, a tree or two on it). Each
arm has an exit from the ring and, just after it (counter-clockwise), an entry into
it. The lane network models every arm as a small junction of its own (a *yield
point*, :attr:`Control.YIELD`) holding three connectors: ring -> ring (through),
ring -> exit lane and entry lane -> ring; the last two merge or cross the first, so
the traffic model's conflict rule makes entering cars wait for circulating ones.
The ring pieces between two arms are connector lanes of the roundabout's own node
(:attr:`Control.NONE`: no request needed) so that their tight curvature limits speed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from dstenv.sim.clutter import obstacles_from
from dstenv.sim.lanes import Control, LaneKind, NetworkBuilder, Turn, bezier, fillet_curve
from dstenv.sim.raster import Surface
from dstenv.sim.types import MapClass, ObstacleKind, Obstacles

__all__ = ["Roundabout", "pick_roundabouts", "add_ring", "ring_nodes", "paint_roundabout",
           "island_clutter"]

RING_WIDTH = 5.5  # [m] paved ring between the island and the outer kerb (one wide lane)
TURN_RADIUS = 5.0  # [m] entries and exits: a right turn of this radius tangent to the ring
MIN_PIECE = 2.0  # [m] shortest ring lane between an entry and the next exit
MIN_ISLAND = 2.0  # [m] smallest central island radius (else the junction stays a junction)
KERB_CLEAR = 0.4  # [m] between the outer ring edge and the block corners' kerbs


@dataclass
class Roundabout:
    """One roundabout.

    Attributes:
        node: the street-graph node it replaces.
        centre: ``(2,) float64`` [m].
        r_out, r_ring, r_island: outer kerb, ring lane centre-line and island radius [m].
        arms: ``(4,) float64`` direction [rad] of each arm seen from the centre (east,
            north, west, south).
        inner: ``(4,) float64`` lateral offset [m] of the innermost lane of each arm
            (entries and exits aim at it; the ring points are placed for it).
        first_node: id of the yield point of the first arm (the others follow).
    """

    node: int
    centre: np.ndarray
    r_out: float
    r_ring: float
    r_island: float
    arms: np.ndarray
    inner: np.ndarray
    first_node: int

    def delta(self, a: int) -> float:
        """Angle [rad] from arm ``a``'s axis to its entry (and from its exit to the axis):
        where a right turn of :data:`TURN_RADIUS` from the arm's inner lane touches the
        ring (circles tangent outside: ``(e + rho) = (R + rho) sin(delta)``)."""
        return float(np.arcsin(min((self.inner[a] + TURN_RADIUS) / (self.r_ring + TURN_RADIUS),
                                   0.99)))

    def fits(self) -> bool:
        """Every ring piece between an entry and the next exit is long enough."""
        return all(self.r_ring * (np.pi / 2 - self.delta(a) - self.delta((a + 1) % 4))
                   >= MIN_PIECE for a in range(4))

    def ring_point(self, ang: float) -> tuple[np.ndarray, float]:
        """Point of the ring lane at polar angle ``ang`` and its (counter-clockwise) heading."""
        return self.centre + self.r_ring * np.array([np.cos(ang), np.sin(ang)]), ang + np.pi / 2

    def arc(self, a0: float, a1: float) -> np.ndarray:
        """Counter-clockwise ring arc from polar angle ``a0`` to ``a1``: ``(K, 2)``."""
        a1 = a0 + (a1 - a0) % (2 * np.pi)
        ang = np.linspace(a0, a1, max(int((a1 - a0) * self.r_ring / 0.4), 3))
        return self.centre + self.r_ring * np.stack([np.cos(ang), np.sin(ang)], -1)


def pick_roundabouts(node_xy: np.ndarray, edges: list, half_x: np.ndarray,
                     half_y: np.ndarray, corner_radius: float, lane_width: float, prob: float,
                     rng: np.random.Generator | None) -> list[Roundabout]:
    """Turn some 4-way junctions of an axis-aligned street grid into roundabouts.

    Args:
        node_xy: ``(J, 2) float64`` junctions [m]; edges: the streets (``RoadEdge``).
        half_x, half_y: ``(J,) float64`` half widths of the street along y (the x
            line) and along x through each node [m].
        corner_radius: kerb radius of the block corners [m] (bounds the ring).
        lane_width: the network's lane width [m] (for edges without their own).
        prob: chance that a 4-way junction becomes a roundabout (one draw per 4-way
            junction, also where the ring would not fit: then it stays a junction).

    Returns:
        The roundabouts, yield-point ids numbered from ``len(node_xy)``.
    """
    if rng is None or prob <= 0:
        return []
    degree = np.zeros(len(node_xy), np.int64)
    inner = np.zeros((len(node_xy), 4))  # inner lane offset of each arm [m]
    for e in edges:
        degree[e.u] += 1
        degree[e.v] += 1
        off = 0.5 * (e.lane_width or lane_width) + 0.5 * e.median
        for n, d in ((e.u, e.poly[1] - e.poly[0]), (e.v, e.poly[-2] - e.poly[-1])):
            inner[n, int(np.round(np.arctan2(d[1], d[0]) / (np.pi / 2))) % 4] = off
    out: list[Roundabout] = []
    for n in np.flatnonzero(degree == 4):
        if rng.random() >= prob:
            continue
        hx, hy = half_x[n], half_y[n]
        r_out = float(np.hypot(hx + corner_radius, hy + corner_radius) - corner_radius
                      - KERB_CLEAR)
        r_island = r_out - RING_WIDTH
        if r_island < MIN_ISLAND:
            continue
        r = Roundabout(int(n), np.asarray(node_xy[n], np.float64), r_out,
                       r_out - RING_WIDTH / 2, r_island,
                       np.array([0.0, np.pi / 2, np.pi, 1.5 * np.pi]), inner[n].copy(),
                       len(node_xy) + 4 * len(out))
        if r.fits():
            out.append(r)
    return out


def ring_nodes(rounds: list[Roundabout]) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``(4R, 2) float64`` [m] and controls ``(4R,) uint8`` of the yield points."""
    xy = [r.ring_point(a)[0] for r in rounds for a in r.arms]
    return np.array(xy).reshape(-1, 2), np.full(len(xy), Control.YIELD, np.uint8)


def add_ring(builder: NetworkBuilder, r: Roundabout, inc: list[tuple], out: list[tuple]) -> None:
    """Add the lanes of one roundabout.

    Args:
        inc, out: the road lanes ending / starting at the roundabout's node as
            ``(lane, edge, k, n, heading, point)`` (``k``: lane index from the inside,
            ``n``: lanes of that direction), as collected by ``add_road_lanes``.
    """
    def arm_of(heading: float, leaving: bool) -> int:
        d = heading if leaving else heading + np.pi
        return int(np.argmin(np.abs(np.angle(np.exp(1j * (r.arms - d))))))

    n_arms = len(r.arms)
    ent = [r.arms[a] + r.delta(a) for a in range(n_arms)]
    ext = [r.arms[a] - r.delta(a) for a in range(n_arms)]
    # ring pieces: from the entry of arm a to the exit of arm a + 1
    piece = [builder.add(r.arc(ent[a], ext[(a + 1) % n_arms]), LaneKind.CONNECTOR, node=r.node,
                         turn=Turn.STRAIGHT, rightmost=True) for a in range(n_arms)]
    for a in range(n_arms):
        node = r.first_node + a
        before, after = piece[(a - 1) % n_arms], piece[a]
        through = builder.add(r.arc(ext[a], ent[a]), LaneKind.CONNECTOR, node=node,
                              turn=Turn.STRAIGHT)
        builder.link(before, through)
        builder.link(through, after)
        p_ext, h_ext = r.ring_point(ext[a])
        p_ent, h_ent = r.ring_point(ent[a])
        for lid, _, k, n, h, p in out:
            if arm_of(h, True) == a and k == 0:  # leave into the inner lane
                c = builder.add(_turn(p_ext, h_ext, p, h), LaneKind.CONNECTOR, node=node,
                                turn=Turn.RIGHT)
                builder.link(before, c)
                builder.link(c, lid)
        for lid, _, k, n, h, p in inc:
            if arm_of(h, False) == a:
                c = builder.add(_turn(p, h, p_ent, h_ent), LaneKind.CONNECTOR, node=node,
                                turn=Turn.RIGHT)
                builder.link(lid, c)
                builder.link(c, after)


def _turn(p0: np.ndarray, h0: float, p1: np.ndarray, h1: float) -> np.ndarray:
    """An entry or exit: straight - arc of :data:`TURN_RADIUS` - straight where the two
    lines leave room, else a smooth cubic curve."""
    poly = fillet_curve(p0, h0, p1, h1, TURN_RADIUS)
    return poly if poly is not None else bezier(p0, h0, p1, h1, n=16, k=0.4)


def paint_roundabout(raster: np.ndarray, surface: np.ndarray, r: Roundabout,
                     res: float) -> None:
    """Pave the ring (road up to ``r_out``) and raise the island (INTERMEDIATE, verge)
    on rasters with origin ``(0, 0)`` and cell size ``res`` [m], in place."""
    lo = np.maximum(np.floor((r.centre - r.r_out) / res).astype(int), 0)
    hi = np.minimum(np.ceil((r.centre + r.r_out) / res).astype(int),
                    np.array(raster.shape[::-1]) - 1)
    cols, rows = np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1)
    d = np.hypot((cols[None, :] + 0.5) * res - r.centre[0],
                 (rows[:, None] + 0.5) * res - r.centre[1])
    win = (slice(lo[1], hi[1] + 1), slice(lo[0], hi[0] + 1))
    ring, island = d <= r.r_out, d <= r.r_island
    raster[win][ring], surface[win][ring] = MapClass.ROAD, Surface.ROAD
    raster[win][island], surface[win][island] = MapClass.INTERMEDIATE, Surface.VERGE


def island_clutter(rounds: list[Roundabout], cfg: dict[str, Any],
                   rng: np.random.Generator | None) -> Obstacles:
    """One or two trees (trunk and crown) on each central island, plus a sign post
    facing each arm where the island is large enough; none when clutter is off."""
    if not rounds or rng is None or cfg["density"] <= 0:
        return Obstacles.empty()
    rows: list[tuple] = []
    for r in rounds:
        n_trees = 1 if r.r_island < 4.0 else int(rng.integers(1, 3))
        for t in range(n_trees):
            off = 0.0 if n_trees == 1 else 0.35 * r.r_island
            p = r.centre + off * np.array([np.cos(np.pi * t), np.sin(np.pi * t)])
            zc = rng.uniform(2.0, 3.0)
            crown = min(rng.uniform(3.0, 6.0), 2 * r.r_island)
            rows.append((p, 0.0, 0.4, 0.4, 0.0, zc + 0.5, ObstacleKind.TREE_TRUNK))
            rows.append((p, 0.0, crown, crown, zc, zc + rng.uniform(3.0, 6.0),
                         ObstacleKind.TREE_CROWN))
        if r.r_island >= 3.0:
            for a in r.arms:
                p = r.centre + (r.r_island - 0.6) * np.array([np.cos(a), np.sin(a)])
                rows.append((p, a + np.pi / 2, 0.1, 0.1, 0.0, 2.3, ObstacleKind.SIGN))
    return obstacles_from(rows)
