"""Right turns go round the painted kerb corner: a car that keeps to its lane stays on
the road (issue 17; measured over many maps by ``docs/bends.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sim import World, default_config, generate_city
from dstenv.sim.ego import hits
from dstenv.sim.lanes import LaneKind, NetworkBuilder, Turn
from dstenv.sim.roads import RoadEdge, add_road_lanes

LW = 3.25  # [m]
KERB_R = 3.45  # [m] the default city's kerb corner: curb strip 2.2 + half a 2.5 m sidewalk
NONE = np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0)


def _leaves_road(wm, lane: int, length: float = 4.5, width: float = 1.9) -> bool:
    """An ego-sized box on the lane centre with the lane's heading, every 0.25 m, is
    somewhere off the road by the env's own rule (:func:`dstenv.sim.ego.hits`)."""
    net = wm.lanes
    s = np.arange(0.0, net.length[lane] + 0.25, 0.25)
    xy, yaw = net.pose(np.full(len(s), lane), s)
    return any(hits(wm, *NONE, (x, y, h, length, width))[1] for (x, y), h in zip(xy, yaw))


@pytest.mark.parametrize("seed", [0, 1])
def test_every_right_turn_of_a_city_keeps_an_ego_box_on_the_road(seed):
    # seeds 0 and 1 each had a right turn (the inner lane of a two-lane street turning
    # into a one-lane street at a bend) whose ego box left the road by 0.3 / 0.6 m
    cfg = default_config()
    wm = generate_city(cfg["map"], cfg["traffic"], np.random.default_rng(seed), cfg["clutter"])
    net = wm.lanes
    rights = np.flatnonzero((net.kind == LaneKind.CONNECTOR) & (net.turn == Turn.RIGHT))
    assert len(rights) > 50
    assert [int(c) for c in rights if _leaves_road(wm, int(c))] == []


def _bend(n_in: int, n_out: int, lw_in: float = LW, lw_out: float = LW):
    """A right-angle bend (a degree-2 node at the origin): a street from the west with
    ``n_in`` lanes per direction turns south with ``n_out``; returns the right-turn
    connectors and the centre of the kerb corner's circle (radius ``KERB_R``)."""
    node_xy = np.array([[0.0, 0.0], [-60.0, 0.0], [0.0, -60.0]])
    edges = [RoadEdge(1, 0, node_xy[[1, 0]], n_in, n_in, lw_in),
             RoadEdge(0, 2, node_xy[[0, 2]], n_out, n_out, lw_out)]
    hw_in, hw_out = n_in * lw_in, n_out * lw_out
    builder = NetworkBuilder()
    trims = np.full(3, max(hw_in, hw_out) + KERB_R + 4.4)
    add_road_lanes(builder, 3, edges, trims, LW, kerb_radius=KERB_R)
    net = builder.build(node_xy, np.zeros(3, np.uint8), np.zeros(3), LW)
    rights = np.flatnonzero((net.kind == LaneKind.CONNECTOR) & (net.turn == Turn.RIGHT))
    # the inside corner: the block west of the south street and south of the west street
    return net, rights, np.array([-hw_out - KERB_R, -hw_in - KERB_R])


@pytest.mark.parametrize("n_in, n_out, lw_in, lw_out", [(2, 1, LW, LW), (1, 2, LW, LW),
                                                        (3, 1, LW, LW), (1, 1, 2.8, 3.7),
                                                        (2, 2, 3.7, 2.8)])
def test_right_turns_at_a_bend_keep_their_lanes_distance_from_the_kerb(n_in, n_out, lw_in,
                                                                       lw_out):
    net, rights, centre = _bend(n_in, n_out, lw_in, lw_out)
    assert len(rights) == n_in  # every incoming lane turns (into the nearest outgoing one)
    for c in rights:
        p = net.polyline(int(c))
        k_in = int(np.argmin(np.abs(p[0, 1] + (np.arange(n_in) + 0.5) * lw_in)))
        k_out = int(np.argmin(np.abs(p[-1, 0] + (np.arange(n_out) + 0.5) * lw_out)))
        gap_in, gap_out = (n_in - k_in - 0.5) * lw_in, (n_out - k_out - 0.5) * lw_out
        # where the lane goes round the corner it stays as far from the kerb (a circle
        # of radius KERB_R) as the nearer of its two lanes is on the straight (less the
        # sag of the chords: points on the arc every <= 0.4 m, resampled every 0.5 m)
        d = np.hypot(*(p - centre).T)
        assert d.min() >= KERB_R + min(gap_in, gap_out) - 0.01
        # a real arc round the corner, not a curve that swings wide of both lanes
        assert d.min() <= KERB_R + max(gap_in, gap_out) + 0.01


def test_autopilot_turns_right_at_a_bend_without_leaving_the_road():
    # seed 1's two-lane street turning into a one-lane street at the map's corner: the
    # ego on the inner lane, driven by autopilot (no traffic) through the right turn
    cfg = {"traffic": {"cars": 0, "cyclists": 0, "pedestrians": 0, "parked_density": 0.0}}
    w = World(cfg, seed=1)
    net = w.map.lanes
    roads = np.flatnonzero((net.kind == LaneKind.ROAD) & ~net.rightmost & (net.length > 20))
    lane, turn = next((int(p), int(c)) for p in roads for c in net.successors(int(p))
                      if net.turn[c] == Turn.RIGHT)
    w.place_ego(lane, float(net.length[lane] - 20.0), speed=6.0)
    assert w.set_turn(Turn.RIGHT) and w.route[1] == turn
    seen = False
    for _ in range(120):
        w.step()
        seen = seen or w.route[0] == turn
        assert not w.off_road
    assert seen and w.route[0] != turn


def _corner_gap(theta_deg: float, ease: float, corner: tuple[int, int], gap: float = 1.625
                ) -> float:
    """Smallest distance [m] between a kerb lane's right turn (an arc ``gap`` from a kerb
    corner of radius ``KERB_R``, and its straights) and the kerb painted ``ease`` larger,
    both through a warp's shear of ``theta_deg``; the block in quadrant ``corner``."""
    from dstenv.sim.warp import Warp

    m = Warp(0.0, 1e9, 0.0, 0.0, 1e9, 0.0, np.deg2rad(theta_deg), np.zeros(2),
             np.zeros(2)).matrix
    sx, sy = corner
    phi = np.linspace(0.0, np.pi / 2, 400)
    towards = np.stack([-sx * np.cos(phi), -sy * np.sin(phi)], -1)  # centre -> corner
    t = np.linspace(0.0, 20.0, 400)
    r = KERB_R + ease
    kerb = np.vstack([np.array([sx, sy]) * r + r * towards,
                      np.stack([sx * (r + t), 0 * t], -1), np.stack([0 * t, sy * (r + t)], -1)])
    lane = np.vstack([np.array([sx, sy]) * KERB_R + (KERB_R + gap) * towards,
                      np.stack([sx * (KERB_R + t), -sy * gap + 0 * t], -1),
                      np.stack([-sx * gap + 0 * t, sy * (KERB_R + t)], -1)])
    k, ln = kerb @ m.T, lane @ m.T
    return float(np.hypot(*(ln[:, None] - k[None]).transpose(2, 0, 1)).min())


@pytest.mark.parametrize("theta", [5.0, 15.0, -15.0, 30.0])
def test_kerb_ease_keeps_a_right_turns_gap_to_the_kerb_through_the_shear(theta):
    from dstenv.sim.warp import kerb_ease

    corners = [(1, 1), (-1, 1), (1, -1), (-1, -1)]
    squeezed = [_corner_gap(theta, 0.0, c) for c in corners]
    assert min(squeezed) < 1.625 - 0.05  # two corners of a block lose clearance
    assert max(squeezed) == pytest.approx(1.625, abs=0.01)  # the other two keep it
    e = kerb_ease(theta, 1.625)
    assert all(_corner_gap(theta, e, c) == pytest.approx(1.625, abs=0.01) for c in corners)
    assert kerb_ease(0.0, 1.625) == 0.0
