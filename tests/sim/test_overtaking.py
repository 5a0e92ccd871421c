"""Double parking, lane changes and overtaking (``dstenv/sim/lanechange.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.grid import GridSpec
from dstenv.dst import CLASSES
from dstenv.sensing import label_grid
from dstenv.sim import World
from dstenv.sim.ego import box_corners, boxes_overlap
from dstenv.sim.lanechange import lane_neighbours
from dstenv.sim.lanes import Control, LaneKind

from .handmade import LW, TRIM, cross_map, lane_ending_near, lane_starting_near

QUIET = {"traffic": {"cars": 0, "cyclists": 0, "pedestrians": 0, "halt_rate": 0.0,
                     "pause_rate": 0.0, "lane_change_rate": 0.0, "lateral_drift": 0.0}}
HOLD = (0.0, 0.0)  # ego action: the ego stands still
BUSY = {"map": {"blocks_x": 3, "blocks_y": 3, "lanes_min": 1, "lanes_max": 2},
        "traffic": {"double_park_prob": 0.3, "halt_rate": 0.03, "lane_change_rate": 0.05,
                    "parked_density": 0.3}}


def _world(lanes):
    w = World(QUIET, seed=0, world_map=cross_map(Control.STOP, lanes))
    net = w.map.lanes
    # the ego stands on the west arm's outbound lane, out of the way
    w.place_ego(lane_starting_near(net, -TRIM, LW / 2), 30.0)
    return w, net


def _stand(w, lane, s, lat=0.0):
    """A car that stays put on ``lane`` at ``s`` (a double-parked car: halted, hazards)."""
    k = w.add_agent(0, lane, s)
    st = w._state
    st["halt"][k], st["hazard"][k] = 1e9, True
    st["lat"][k] = st["lat_goal"][k] = lat
    w.step(HOLD)
    return k


def _overlaps(w):
    a = w.agents
    c = np.concatenate([a.corners(), box_corners(*w.ego_pose, *w.ego_size)[None]])
    centres = c.mean(1)
    n = 0
    for i in range(len(c)):
        near = np.flatnonzero(np.hypot(*(centres - centres[i]).T) < 9.0)
        near = near[near > i]
        n += int(len(near) > 0 and boxes_overlap(c[i], c[near]).any())
    return n


def test_lane_neighbours_of_a_two_lane_street_by_hand():
    net = cross_map(Control.STOP, 2).lanes
    # south arm, northbound: inner lane at x = LW/2, kerb lane at x = 3 LW/2; southbound
    # inner lane at x = -LW/2 (its oncoming lane)
    inner = lane_ending_near(net, LW / 2, -TRIM)
    kerb = lane_ending_near(net, 1.5 * LW, -TRIM)
    onc = lane_starting_near(net, -LW / 2, -TRIM)
    left, right, opp = lane_neighbours(net)
    assert (left[kerb], right[kerb], opp[kerb]) == (inner, -1, -1)
    assert (left[inner], right[inner], opp[inner]) == (-1, kerb, onc)
    assert opp[onc] == inner
    assert (left[net.kind != LaneKind.ROAD] == -1).all()
    one = cross_map(Control.STOP, 1).lanes
    l1, r1, o1 = lane_neighbours(one)
    lane = lane_ending_near(one, LW / 2, -TRIM)
    assert (l1[lane], r1[lane], o1[lane]) == (-1, -1, lane_starting_near(one, -LW / 2, -TRIM))


def test_double_parked_cars_stand_static_in_the_kerb_lane_then_drive_off():
    cfg = {"map": {"blocks_x": 3, "blocks_y": 3},
           "traffic": {"double_park_prob": 1.0, "parked_density": 0.3,
                       "double_park_duration": 3.0}}
    w = World(cfg, seed=2)
    st, net = w._state, w.map.lanes
    dp = np.flatnonzero(st["hazard"])
    assert len(dp) >= 5 and not st["parked"][dp].any()
    lanes = st["route"][dp, 0]
    assert (net.kind[lanes] == LaneKind.ROAD).all() and net.rightmost[lanes].all()
    assert (st["v"][dp] == 0).all() and (st["lat"][dp] < 0).all()  # kerb side of the lane
    spec = GridSpec()
    start = w.agents.xy[dp].copy()
    labels = label_grid(w.map, w.agents, w.ego_pose, spec)
    seen = 0
    x, y, yaw = w.ego_pose
    for i in dp:  # the label of a visible double-parked car is static
        dx, dy = start[list(dp).index(i)] - (x, y)
        ex, ey = np.cos(yaw) * dx + np.sin(yaw) * dy, -np.sin(yaw) * dx + np.cos(yaw) * dy
        r, c = spec.to_cell(np.array(ex), np.array(ey))
        if spec.inside(r, c):
            assert CLASSES[labels[int(r), int(c)]] == "static"
            seen += 1
    for _ in range(130):  # dwell at most 4 x 3 s
        w.step()
    st = w._state
    assert not st["hazard"][dp].any()
    moved = np.hypot(*(w.agents.xy[dp] - start).T)
    assert (moved > 3.0).mean() > 0.5  # most drove off into the traffic


def test_car_changes_lane_to_pass_a_double_parked_car():
    w, net = _world(2)
    kerb = lane_ending_near(net, 1.5 * LW, -TRIM)
    inner = lane_ending_near(net, LW / 2, -TRIM)
    blk = _stand(w, kerb, 30.0, lat=-0.5)
    car = w.add_agent(0, kerb, 5.0, speed=8.0)
    passed = None
    for step in range(200):
        w.step(HOLD)
        assert _overlaps(w) == 0
        a = w.agents
        if passed is None and a.xy[car, 1] - a.xy[blk, 1] > (a.length[car] + a.length[blk]) / 2:
            passed = step
            assert w.agent_lanes[car] == inner
            assert abs(a.xy[car, 0] - LW / 2) < 0.9  # in the inner lane beside it
        if passed is not None and a.xy[car, 1] > -TRIM - 5:
            break
    assert passed is not None and passed < 120
    assert w.agents.speed[blk] == 0.0


def test_one_lane_street_passes_a_standing_car_on_the_free_oncoming_lane():
    w, net = _world(1)
    lane = lane_ending_near(net, LW / 2, -TRIM)
    blk = _stand(w, lane, 25.0)
    car = w.add_agent(0, lane, 2.0, speed=8.0)
    lats, passed = [], False
    for _ in range(250):
        w.step(HOLD)
        assert _overlaps(w) == 0
        a = w.agents
        lats.append(a.xy[car, 0])
        passed |= a.xy[car, 1] - a.xy[blk, 1] > (a.length[car] + a.length[blk]) / 2 + 2.0
        if passed and abs(a.xy[car, 0] - LW / 2) < 0.05:
            break
    assert passed
    assert min(lats) < -LW / 2 + 0.3  # it was on the oncoming lane (centre x = -LW/2)
    assert abs(w.agents.xy[car, 0] - LW / 2) < 0.05  # and back in its own lane
    assert w.agent_lanes[car] == lane  # (not into the junction)


def test_one_lane_street_queues_when_the_oncoming_lane_is_blocked():
    w, net = _world(1)
    lane = lane_ending_near(net, LW / 2, -TRIM)
    blk = _stand(w, lane, 30.0)
    onc = lane_starting_near(net, -LW / 2, -TRIM)  # runs south, from the junction
    _stand(w, onc, 22.0)  # a car standing on the oncoming lane, 8 m further down
    car = w.add_agent(0, lane, 2.0, speed=10.0)
    for _ in range(200):
        w.step(HOLD)
        a = w.agents
        gap = w._state["s"][blk] - w._state["s"][car] - (a.length[blk] + a.length[car]) / 2
        assert gap > 0.5 and abs(a.xy[car, 0] - LW / 2) < 0.05
    assert w.agents.speed[car] < 0.1  # queued: static
    assert 1.0 < gap < 4.0  # about the jam distance (2 m)


def test_oncoming_traffic_waits_out_then_the_pass_follows():
    w, net = _world(1)
    lane = lane_ending_near(net, LW / 2, -TRIM)
    blk = _stand(w, lane, 25.0)
    onc = lane_starting_near(net, -LW / 2, -TRIM)
    other = w.add_agent(0, onc, 2.0, speed=10.0)  # coming the other way, drives on
    car = w.add_agent(0, lane, 2.0, speed=8.0)
    met = False
    for _ in range(300):
        w.step(HOLD)
        assert _overlaps(w) == 0
        a = w.agents
        if a.xy[other, 1] > a.xy[car, 1]:  # not met yet: the car has not left its lane
            assert abs(a.xy[car, 0] - LW / 2) < 0.3
        else:
            met = True
        if a.xy[car, 1] > a.xy[blk, 1] + 8.0:
            break
    assert met and w.agents.xy[car, 1] > w.agents.xy[blk, 1] + 8.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_no_boxes_overlap_in_busy_traffic_with_lane_changes(seed):
    w = World(BUSY, seed=seed)
    changes = 0
    for _ in range(300):
        before = w._state["route"][:, 0].copy()
        w.step()
        assert _overlaps(w) == 0
        after = w._state["route"][:, 0]
        if len(before) == len(after):
            changes += int(((w._state["lc"] == -1) & (before != after)).sum())
    assert changes >= 1


def test_same_seed_same_trajectories_with_lane_changes():
    runs = []
    for _ in range(2):
        w = World(BUSY, seed=4)
        xs, lcs = [], []
        for _ in range(120):
            w.step()
            xs.append(w.agents.xy.copy())
            lcs.append(w._state["lc"].copy())
        runs.append((xs, lcs))
    for a, b in zip(runs[0][0], runs[1][0]):
        assert np.array_equal(a, b)
    assert any((lc != 0).any() for lc in runs[0][1])


def test_new_knobs_are_validated_by_name():
    for key, bad in (("double_park_prob", 1.5), ("lane_change_rate", -0.1),
                     ("lane_change_time", 0.1), ("double_park_duration", -1.0)):
        with pytest.raises(ValueError, match=f"traffic.{key}"):
            World({"traffic": {key: bad}}, seed=0)



def test_default_city_changes_lanes_and_passes_halted_vehicles():
    """Issue 12: in the shipped default scenario (not boosted rates) vehicles change lanes
    and get past halted delivery vans / double-parked cars on their own."""
    from dstenv.scenario_files import load_scenario
    from dstenv.sim import default_config

    w = World(load_scenario("default", {"world": default_config()})["world"], seed=0)
    st = w._state
    changes = passes = past_halted = 0
    for _ in range(1500):  # 150 s
        lane0, lc0, s0 = st["route"][:, 0].copy(), st["lc"].copy(), st["s"].copy()
        halted = (st["halt"] > 0) | st["hazard"]
        w.step()
        moved = np.flatnonzero((st["lc"] == -1) & (lane0 != st["route"][:, 0]) & (lc0 != -1))
        borrow = np.flatnonzero((st["lc"] > 0) & (lc0 <= 0))  # onto the oncoming lane
        changes, passes = changes + len(moved), passes + len(borrow)
        for i in np.concatenate([moved, borrow]):  # a halted vehicle ahead on its old lane
            ahead = (lane0 == lane0[i]) & halted & (s0 > s0[i]) & (s0 - s0[i] < 45.0)
            past_halted += int(ahead.any())
    assert changes >= 20 and passes >= 1 and past_halted >= 2
