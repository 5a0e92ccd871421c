"""The world's public API for RL: map pool, keep_map, route steering, next junction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.sim import World
from dstenv.sim.ego import pursuit_lookahead
from dstenv.sim.lanes import Control

from .handmade import TRIM, cross_map, lane_ending_near

TINY = {"map": {"blocks_x": 2, "blocks_y": 2},
        "traffic": {"cars": 4, "cyclists": 0, "pedestrians": 2}}


def test_map_pool_draws_from_n_maps_generated_once():
    w = World({**TINY, "map": {**TINY["map"], "pool": 3}}, seed=0)
    maps = {}
    for seed in range(12):
        w.reset(seed)
        assert 0 <= w.map_index < 3
        maps.setdefault(w.map_index, w.map)
        assert w.map is maps[w.map_index]  # generated once, then reused
    assert len(maps) == 3
    # map k is the same in another process / world: it depends on k only
    other = World({**TINY, "map": {**TINY["map"], "pool": 3}}, seed=0)
    for seed in range(12):
        other.reset(seed)
        assert np.array_equal(other.map.raster, maps[other.map_index].raster)


def test_keep_map_on_a_pool_map_keeps_its_index():
    w = World({**TINY, "map": {**TINY["map"], "pool": 3}}, seed=0)
    w.reset(5)
    k, city = w.map_index, w.map
    w.reset(6, keep_map=True)
    assert w.map is city and w.map_index == k >= 0


def test_without_pool_every_seed_has_its_map_and_keep_map_keeps_it():
    w = World(TINY, seed=0)
    first = w.map
    w.reset(1)
    assert w.map is not first and w.map_index == -1
    assert (not np.array_equal(w.map.raster, first.raster)
            or w.map.raster.shape != first.raster.shape)
    kept = w.map
    w.reset(2, keep_map=True)
    assert w.map is kept
    pose_a = w.ego_pose.copy()
    w.reset(2, keep_map=True)  # the same seed on the same map replays the episode
    assert np.array_equal(w.ego_pose, pose_a)


def test_pool_must_be_non_negative():
    with pytest.raises(ConfigError, match=r"world.map.pool: must be in \[0, 1000\], got -1"):
        World({"map": {"pool": -1}})


def test_autopilot_steers_with_the_public_route_rule():
    w = World(TINY, seed=4)
    for _ in range(80):
        expected = w.route_steer()
        w.step()
        assert w.ego_steer == expected
    assert not w.off_road


def test_route_steer_is_pure_pursuit_of_the_rear_axle():
    w = World(seed=0, world_map=cross_map())
    lane = lane_ending_near(w.map.lanes, -TRIM, -1.6)  # eastbound towards the junction
    w.place_ego(lane, 20.0, speed=5.0)
    x, y, yaw = w.ego_pose
    look = pursuit_lookahead(5.0)
    assert look == pytest.approx(4.5)
    # a straight lane: the target lies on the lane ahead, so steering only corrects the
    # (zero) offset
    assert abs(w.route_steer()) < 1e-6
    assert yaw == pytest.approx(0.0, abs=1e-9)
    # 90 deg off the lane: the rear axle's target lies to the right, at full lock
    w.place_ego(lane, 20.0, speed=5.0)
    w._state["yaw"][-1] = math.pi / 2  # test-only: turn the ego in place
    assert w.route_steer() == pytest.approx(-w.config["ego"]["max_steer"])


@pytest.mark.parametrize("control", [Control.STOP, Control.SIGNAL])
def test_next_junction_distance_and_control(control):
    w = World(seed=0, world_map=cross_map(control))
    net = w.map.lanes
    lane = lane_ending_near(net, -TRIM, -1.6)
    w.place_ego(lane, 20.0)
    dist, ctl, green = w.next_junction()
    assert dist == pytest.approx(net.length[lane] - 20.0)
    assert ctl == control
    if control == Control.STOP:
        assert green is False
    else:  # signal offset 0, group of the ego's connector: green at t = 0 for group 0
        conn = int(w.route[1])
        assert green == (int(net.group[conn]) == 0)


def test_next_junction_of_a_crossing_built_uncontrolled_is_a_yield():
    # paths that cross need a right-of-way rule: the network turns an uncontrolled
    # node whose connectors conflict into a yield junction (first come, first served)
    w = World(seed=0, world_map=cross_map(Control.NONE))
    assert w.map.lanes.node_control[0] == Control.YIELD  # the crossing; dead ends stay NONE
    lane = lane_ending_near(w.map.lanes, -TRIM, -1.6)
    w.place_ego(lane, 5.0)
    dist, ctl, green = w.next_junction()
    assert ctl == Control.YIELD and not green
    assert math.isinf(dist) or dist >= 0
