"""The generated world: determinism, no overlaps, no agent in buildings, the ego."""

import math

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.sim import World, default_config
from dstenv.sim.ego import bicycle_step, box_corners, boxes_overlap
from dstenv.sim.lanes import LaneKind
from dstenv.sim.raster import lookup
from dstenv.sim.types import AgentKind, MapClass
from .clean import clean_world

SMALL = {"map": {"blocks_x": 3, "blocks_y": 3},
         "traffic": {"cars": 16, "cyclists": 3, "pedestrians": 16, "crossing_prob": 0.8}}


def _snapshot(w):
    a = w.agents
    return [a.xy, a.yaw, a.speed, a.kind, a.parked, w.ego_pose, np.array([w.ego_speed])]


def test_same_seed_gives_bit_identical_worlds_and_trajectories():
    runs = []
    for _ in range(2):
        w = World(SMALL, seed=7)
        m = w.map
        for _ in range(60):
            w.step()
        runs.append((m, _snapshot(w), w.route_progress))
    (m1, s1, p1), (m2, s2, p2) = runs
    assert np.array_equal(m1.raster, m2.raster)
    assert len(m1.buildings) == len(m2.buildings)
    assert all(np.array_equal(a, b) for a, b in zip(m1.buildings, m2.buildings))
    assert all(np.array_equal(a, b) for a, b in zip(s1, s2))
    assert p1 == p2
    other = World(SMALL, seed=8)
    assert other.map.raster.shape != m1.raster.shape or \
        not np.array_equal(other.map.raster, m1.raster)


def test_reset_with_the_same_seed_replays_the_episode():
    w = World(SMALL, seed=3)
    for _ in range(30):
        w.step((0.5, 0.05))
    first = _snapshot(w)
    w.reset(3)
    assert w.time == 0.0 and w.route_progress == 0.0
    for _ in range(30):
        w.step((0.5, 0.05))
    assert all(np.array_equal(a, b) for a, b in zip(first, _snapshot(w)))


def test_agents_never_overlap_nor_enter_buildings_and_autopilot_stays_on_road():
    w = World(SMALL, seed=11)
    kinds_seen_crossing = False
    for _ in range(400):
        w.step()
        a = w.agents
        corners = np.concatenate([a.corners(), box_corners(*w.ego_pose, *w.ego_size)[None]])
        centres = corners.mean(1)
        for i in range(len(corners)):
            near = np.flatnonzero(np.hypot(*(centres - centres[i]).T) < 7.0)
            near = near[near > i]
            assert not boxes_overlap(corners[i], corners[near]).any()
        assert not (lookup(w.map, corners.reshape(-1, 2)) == MapClass.BUILDING).any()
        assert not w.collision and not w.off_road
        walkers = a.kind == AgentKind.PEDESTRIAN
        on = w.map.lanes.kind[w.agent_lanes[walkers]]
        kinds_seen_crossing |= bool((on == LaneKind.CROSSING).any())
    assert w.route_progress > 60.0
    assert kinds_seen_crossing  # pedestrians do cross streets


def test_cars_stand_and_drive():
    w = World(SMALL, seed=5)
    speeds = []
    for _ in range(300):
        w.step()
        a = w.agents
        speeds.append(a.speed[(a.kind == AgentKind.CAR) & ~a.parked])
    s = np.concatenate(speeds)
    assert (s < 0.1).mean() > 0.02  # some cars wait (junctions, queues) ...
    assert (s > 3.0).mean() > 0.3  # ... most drive
    assert (w.agents.speed[w.agents.parked] == 0).all()


def test_generated_network_is_routable():
    net = World(SMALL, seed=2).map.lanes
    for lane in range(len(net)):
        succ = net.successors(lane)
        assert len(succ) >= 1, f"lane {lane} ({LaneKind(net.kind[lane]).name}) is a dead end"
        if net.kind[lane] == LaneKind.CONNECTOR:
            assert len(succ) == 1 and net.kind[succ[0]] == LaneKind.ROAD
        end, first = net.polyline(lane)[-1], net.polyline(succ[0])[0]
        assert np.hypot(*(end - first)) < 1e-6  # lanes join without jumps
    road_pts = np.vstack([net.polyline(k) for k in np.flatnonzero(net.kind <= LaneKind.CONNECTOR)])
    walk_pts = np.vstack([net.polyline(k) for k in np.flatnonzero(net.kind == LaneKind.SIDEWALK)])
    m = World(SMALL, seed=2).map
    assert (lookup(m, road_pts) == MapClass.ROAD).all()
    assert (lookup(m, walk_pts) == MapClass.INTERMEDIATE).all()


def test_bicycle_straight_constant_acceleration():
    x, y, yaw, v = 0.0, 0.0, 0.0, 2.0
    for _ in range(10):
        x, y, yaw, v = bicycle_step(x, y, yaw, v, 1.0, 0.0, 2.7, 0.1, 30.0)
    assert v == pytest.approx(3.0)
    assert x == pytest.approx(2.0 * 1.0 + 0.5 * 1.0 * 1.0 ** 2)  # v0 t + a t^2 / 2
    assert y == 0.0 and yaw == 0.0


def test_bicycle_quarter_circle_by_hand():
    # tan(steer) = 2 -> slip beta = atan(1) = pi/4; centre path radius R = L / (2 sin beta)
    wheelbase = 2.7
    radius = wheelbase / (2 * math.sin(math.pi / 4))
    v = radius * math.pi / 2  # one 1-s step covers a quarter circle
    x, y, yaw, v1 = bicycle_step(0.0, 0.0, 0.0, v, 0.0, math.atan(2.0), wheelbase, 1.0, 100.0)
    # circle centre at (-L/2, L/2); after a quarter turn the centre of the car is at (0, L)
    assert (x, y) == (pytest.approx(0.0, abs=1e-12), pytest.approx(wheelbase))
    assert yaw == pytest.approx(math.pi / 2) and v1 == v


def test_bicycle_braking_stops_without_reversing():
    x, y, yaw, v = bicycle_step(0.0, 0.0, 0.0, 1.0, -5.0, 0.0, 2.7, 1.0, 30.0)
    assert v == 0.0 and x == pytest.approx(0.1)  # v^2 / (2 |a|)


def test_controlled_ego_follows_the_bicycle_model_and_flags_collisions():
    w = World(clean_world(SMALL), seed=4)
    x0, y0, yaw0 = w.ego_pose
    w.step((2.0, 0.0))
    x1, y1, yaw1 = w.ego_pose
    d = 0.5 * 2.0 * w.config["dt"] ** 2 + w.config["ego"]["initial_speed"] * w.config["dt"]
    assert math.hypot(x1 - x0, y1 - y0) == pytest.approx(d)
    assert yaw1 == pytest.approx(yaw0)
    for _ in range(300):  # full throttle, hard left: it leaves the road or hits something
        w.step((3.0, 0.6))
        if w.off_road or w.collision:
            break
    assert w.off_road or w.collision


def test_driving_task_places_traffic_near_the_route():
    cfg = {"map": {"blocks_x": 3, "blocks_y": 3, "parking_prob": 1.0},
           "traffic": {"cars": 0, "cyclists": 0, "pedestrians": 0, "parked_density": 0.0},
           "task": {"cross_traffic": 2, "parked_near_route": 4, "crossing_pedestrians": 1}}
    w = World(cfg, seed=1)
    a = w.agents
    assert ((a.kind == AgentKind.CAR) & ~a.parked).sum() == 2
    assert a.parked.sum() == 4
    assert (a.kind == AgentKind.PEDESTRIAN).sum() == 1
    route = w.route_polyline(500.0)
    assert all(np.hypot(*(route - p).T).min() < 45.0 for p in a.xy)


@pytest.mark.parametrize("override, key", [
    ({"map": {"lanes_max": 4}}, "world.map.lanes_max"),
    ({"map": {"kind": "moon"}}, "world.map.kind"),
    ({"traffic": {"parked_density": 1.5}}, "world.traffic.parked_density"),
    ({"dt": 0.0}, "world.dt"),
])
def test_bad_values_are_named(override, key):
    with pytest.raises(ConfigError, match=key):
        World(override, seed=0)


def test_unknown_key_lists_allowed_keys():
    with pytest.raises(ConfigError,
                       match=r"world\.traffic\.carz: unknown key 'carz'; allowed keys: .*cars"):
        World({"traffic": {"carz": 3}}, seed=0)


def test_default_config_sections():
    cfg = default_config()
    assert set(cfg) == {"dt", "map", "traffic", "clutter", "ego", "task"}
    assert cfg["dt"] == 0.1
    assert default_config() is not cfg  # a fresh dict each call


def test_a_stuck_agent_is_replaced_out_of_sight():
    w = World(SMALL, seed=6)
    st = w._state
    kinds = w.agents.kind
    car = int(np.flatnonzero(st["mobile"][:-1] & (kinds == AgentKind.CAR))[0])
    walker = int(np.flatnonzero(kinds == AgentKind.PEDESTRIAN)[0])
    before = w.agents.xy.copy()
    st["stuck"][[car, walker]] = True  # as the traffic step flags gridlocked agents
    w.step()
    a = w.agents
    for i, lane_kind in ((car, LaneKind.ROAD), (walker, LaneKind.SIDEWALK)):
        assert not w._state["stuck"][i]
        assert np.hypot(*(a.xy[i] - before[i])) > 1.0
        assert np.hypot(*(a.xy[i] - w.ego_pose[:2])) >= 60.0
        assert w.map.lanes.kind[w.agent_lanes[i]] == lane_kind


def test_set_turn_replans_the_next_junction():
    from dstenv.sim.lanes import LaneKind, Turn

    outcomes = {Turn.LEFT: 0, Turn.RIGHT: 0}
    for seed in range(4):
        world = World(seed=seed)
        net = world.map.lanes
        for _ in range(6):
            for _ in range(25):
                world.step()
            for turn in outcomes:
                before = world.route
                if world.set_turn(turn):
                    route = world.route
                    k = next(i for i in range(1, len(route))
                             if net.kind[route[i]] == LaneKind.CONNECTOR)
                    assert net.turn[route[k]] == turn
                    assert np.array_equal(route[:k], before[:k])  # up to the junction: same
                    outcomes[turn] += 1
                else:
                    assert np.array_equal(world.route, before)
            assert not world.collision and not world.off_road
    assert outcomes[Turn.LEFT] > 0 and outcomes[Turn.RIGHT] > 0
