"""The highway-env world source (dstenv.sim.highway) and the DSTGridObservation wrapper."""

from __future__ import annotations

import gymnasium as gym
import highway_env  # noqa: F401
import numpy as np
import pytest
from highway_env.road.lane import StraightLane

from dstenv.config import ConfigError
from dstenv.envs import DSTGridObservation
from dstenv.sim.highway import HighwayWorld
from dstenv.sim.highway_map import place_buildings, rasterise_lanes
from dstenv.sim.types import MapClass


def test_rasterise_straight_lane_is_mirrored_and_exact():
    # highway-env lane along +x at y = +10 (its y-down frame), 4 m wide, 20 m long
    lane = StraightLane([0.0, 10.0], [20.0, 10.0], width=4.0)
    raster = rasterise_lanes([lane], bounds=(-5.0, 25.0, -20.0, 20.0), resolution=0.5)
    assert raster.shape == (80, 60)
    rows, cols = np.nonzero(raster == MapClass.ROAD)
    # mirrored: world y in [-12, -8) -> rows (y + 20) / 0.5 in [16, 24)
    assert rows.min() == 16 and rows.max() == 23
    # x in [0, 20] -> columns 10 .. 50 (the end point's cell included)
    assert cols.min() == 10 and cols.max() == 50
    assert (raster[16:24, 10:50] == MapClass.ROAD).all()
    assert set(np.unique(raster)) == {MapClass.ROAD, MapClass.INTERMEDIATE}


def test_buildings_keep_setback_and_are_seeded():
    lane = StraightLane([0.0, 0.0], [100.0, 0.0], width=4.0)
    base = rasterise_lanes([lane], (0.0, 100.0, -50.0, 50.0), 0.5)
    cfg = {"per_hectare": 20.0, "size_min": 5.0, "size_max": 10.0, "setback": 3.0, "gap": 2.0}
    r1, r2 = base.copy(), base.copy()
    b1 = place_buildings(r1, (0.0, -50.0), 0.5, cfg, np.random.default_rng(7))
    b2 = place_buildings(r2, (0.0, -50.0), 0.5, cfg, np.random.default_rng(7))
    assert len(b1) > 5
    assert np.array_equal(r1, r2) and all(np.array_equal(a, b) for a, b in zip(b1, b2))
    # the road occupies |y| < 2 m; every building keeps >= 3 m from it
    for poly in b1:
        ys = poly[:, 1]
        assert ys.min() >= 2.0 + 3.0 - 1e-9 or ys.max() <= -2.0 - 3.0 + 1e-9
    assert (r1 == MapClass.BUILDING).sum() > 0 and (r1[r1 != base] == MapClass.BUILDING).all()


def test_highway_world_mirrors_poses_and_agents():
    w = HighwayWorld({"scene": "intersection-v1", "resolution": 0.5}, seed=3)
    ego = w.ego_vehicle
    assert np.allclose(w.ego_pose, [ego.position[0], -ego.position[1], -ego.heading])
    others = [v for v in w.env.unwrapped.road.vehicles if v is not ego]
    assert len(w.agents) == len(others)
    assert np.allclose(w.agents.xy[:, 1], [-v.position[1] for v in others])
    # the ego starts on a lane: its map cell is road
    x0, y0 = w.map.origin
    col = int((w.ego_pose[0] - x0) / w.map.resolution)
    row = int((w.ego_pose[1] - y0) / w.map.resolution)
    assert w.map.raster[row, col] == MapClass.ROAD
    assert len(w.map.buildings) > 0


def test_continuous_steering_left_turns_counter_clockwise():
    yaws = {}
    for steer in (0.2, -0.2):
        w = HighwayWorld({"scene": "highway-fast-v0", "action_mode": "continuous",
                          "resolution": 1.0}, seed=0)
        yaw0 = w.ego_pose[2]
        for _ in range(5):
            w.step((0.0, steer))
        yaws[steer] = w.ego_pose[2] - yaw0
    assert yaws[0.2] > 0.01 and yaws[-0.2] < -0.01
    assert w.time == pytest.approx(0.5)


def test_meta_action_names_are_checked():
    w = HighwayWorld({"scene": "highway-fast-v0", "resolution": 1.0}, seed=0)
    with pytest.raises(ValueError, match="meta-action 'JUMP' not available"):
        w.step("JUMP")
    with pytest.raises(ConfigError, match="unknown scene 'nope'"):
        HighwayWorld({"scene": "nope"})


def test_wrapper_gives_grid_observations_and_keeps_env_reward():
    base = gym.make("intersection-v2", config={"simulation_frequency": 10, "policy_frequency": 10})
    env = DSTGridObservation(base, config={"grid": {"height": 40, "width": 40, "cell_size": 1.0},
                                           "lidar": {"beams": 360}, "highway": {"resolution": 0.5},
                                           "info": {"lidar_points": True, "labels": True}})
    obs, info = env.reset(seed=5)
    assert obs.shape == (4, 40, 40) and obs.dtype == np.uint8
    assert env.observation_space.contains(obs)
    assert info["labels"].shape == (40, 40) and info["lidar_points"].shape == (360, 2)
    obs2, reward, term, trunc, info = env.step(env.action_space.sample())
    assert isinstance(reward, float) and "speed" in info  # highway-env's own info kept
    assert info["visible"].any()
    # the same seed reproduces the episode
    a, _ = env.reset(seed=5)
    assert np.array_equal(a, obs)
