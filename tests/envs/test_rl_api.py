"""What an RL user relies on: the dict observation, episode outcome in info, action
meanings, fixed spaces, the autopilot action, wrapper and rendering conventions."""

from __future__ import annotations

import math

import gymnasium as gym
import highway_env  # noqa: F401  (registers intersection-v2)
import numpy as np
import pytest

import dstenv  # noqa: F401
from dstenv.config import ConfigError
from dstenv.envs import DSTGridEnv, DSTGridObservation
from dstenv.envs.navigation import EGO_FEATURES, JUNCTION_RANGE, SPEED_SCALE
from dstenv.sim.types import AgentKind

from .conftest import SMALL_CITY, SMALL_HIGHWAY

F = {name: i for i, name in enumerate(EGO_FEATURES)}


def test_dict_observation_holds_ego_state_and_route():
    env = gym.make("DSTGrid-Occluded-v0", config=SMALL_CITY)
    obs, info = env.reset(seed=4)
    world = env.unwrapped.pipeline.world
    assert env.observation_space.contains(obs) and set(obs) == {"grid", "ego", "route"}
    assert obs["ego"][F["target_speed"]] == pytest.approx(9.0 / SPEED_SCALE)
    prev_speed = 0.0
    for t in range(12):
        action = 2 if t < 8 else (0 if t == 8 else 1)  # FASTER, one SLOWER, IDLE
        obs, _, terminated, truncated, info = env.step(action)
        ego = obs["ego"]
        assert ego[F["speed"]] == pytest.approx(info["ego_speed"] / SPEED_SCALE, abs=1e-6)
        accel = (info["ego_speed"] - prev_speed) / 0.1
        assert ego[F["accel"]] == pytest.approx(np.clip(accel / 5.0, -1, 1), abs=1e-5)
        assert ego[F["steer"]] == pytest.approx(world.ego_steer / 0.6, abs=1e-6)
        dist, control, green = world.next_junction()
        if dist <= JUNCTION_RANGE:
            assert ego[F["junction_dist"]] == pytest.approx(dist / JUNCTION_RANGE, abs=1e-6)
            assert ego[F["control_none"] + int(control)] == 1.0
            assert ego[F["signal_green"]] == float(green)
        assert ego[F["control_none"]:F["control_signal"] + 1].sum() == 1.0
        # route points 5, 10, ... 40 m ahead, in the ego frame, scaled by 40 m
        pts = obs["route"].reshape(8, 2) * 40.0
        x, y, yaw = info["ego_pose"]
        ref = world.route_polyline(40.0, 5.0)[1:]
        c, s = math.cos(yaw), math.sin(yaw)
        d = ref - [x, y]
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], 1)
        # (the observation clips to +-40 m: a point 40.002 m ahead reads 40)
        np.testing.assert_allclose(pts, np.clip(local, -40.0, 40.0), atol=1e-3)
        prev_speed = info["ego_speed"]
        assert not (terminated or truncated)
    assert obs["ego"][F["target_speed"]] == pytest.approx(4.5 / SPEED_SCALE)
    env.close()


def test_info_reports_progress_success_and_termination_reason():
    env = gym.make("DSTGrid-RL-v0", config={**SMALL_CITY, "info": {"success_distance": 5.0}})
    _, info = env.reset(seed=1)
    assert info["route_progress"] == 0.0 and info["is_success"] is False
    world = env.unwrapped.pipeline.world
    for _ in range(40):
        _, _, terminated, _, info = env.step(2)
        assert info["route_progress"] == pytest.approx(world.route_progress, abs=1e-9)
        if terminated:
            break
    assert info["route_progress"] > 5.0
    assert info["is_success"] == (not terminated) and info["termination_reason"] in (
        "timeout", "collision", "off_road")
    # a car parked right in front of the ego: the next step is a collision
    _, info = env.reset(seed=1)
    lane, s = int(world.route[0]), float(world._state["s"][-1])
    world.add_agent(AgentKind.CAR, lane, min(s + 3.0, world.map.lanes.length[lane]))
    _, reward, terminated, _, info = env.step(1)
    assert terminated and info["collision"]
    assert info["termination_reason"] == "collision" and info["is_success"] is False
    env.close()


@pytest.mark.parametrize("kind,names", [
    ("discrete", ["SLOWER", "IDLE", "FASTER", "LEFT", "RIGHT"]),
    ("speed", ["SLOWER", "IDLE", "FASTER"]),
    ("autopilot", ["AUTOPILOT"]),
])
def test_action_meanings_and_spaces_depend_on_the_type_only(kind, names):
    for cfg in (SMALL_CITY, SMALL_HIGHWAY) if kind != "autopilot" else (SMALL_CITY,):
        env = DSTGridEnv({**cfg, "action": {"type": kind}})
        assert env.get_action_meanings() == names
        assert env.action_space == gym.spaces.Discrete(len(names))


def test_highway_has_no_autopilot_to_drive():
    # its IDLE only keeps lane and speed: no 'autopilot' row that is IDLE by another name
    with pytest.raises(ConfigError, match="config.action.type: 'autopilot' is the city world's "
                                          "driver; highway-env's world has none"):
        DSTGridEnv({**SMALL_HIGHWAY, "action": {"type": "autopilot"}})


def test_continuous_has_no_meanings_and_turns_is_gone():
    env = DSTGridEnv({**SMALL_HIGHWAY, "action": {"type": "continuous"}})
    with pytest.raises(TypeError, match="continuous"):
        env.get_action_meanings()
    with pytest.raises(ConfigError, match="config.action.turns: unknown key"):
        DSTGridEnv({**SMALL_CITY, "action": {"turns": False}})
    with pytest.raises(ConfigError, match="known: discrete, speed, continuous, autopilot"):
        DSTGridEnv({**SMALL_CITY, "action": {"type": "meta"}})


def test_a_continuous_action_of_the_wrong_size_or_nan_is_named():
    env = DSTGridEnv({**SMALL_CITY, "action": {"type": "continuous"}})
    env.reset(seed=0)
    for bad in ([0.0, 0.0, 0.0], [float("nan"), 0.0], [0.5]):
        with pytest.raises(ValueError, match=r"continuous action: expected 2 finite numbers"):
            env.step(np.array(bad, np.float32))
    env.step(np.array([0.2, 0.0], np.float32))  # the env still steps after a refused action
    env.close()


def test_autopilot_action_drives_like_the_world():
    from dstenv.sim import World

    env = gym.make("DSTGrid-RL-v0", config={**SMALL_CITY, "action": {"type": "autopilot"}})
    _, info = env.reset(seed=5)
    world = World(env.unwrapped.config["world"], info["seed"])
    for _ in range(15):
        _, _, _, _, info = env.step(0)
        world.step(None)
        np.testing.assert_array_equal(world.ego_pose, info["ego_pose"])
    assert info["ego_speed"] > 0.5
    env.close()


def test_meta_actions_steer_with_the_world_rule():
    env = gym.make("DSTGrid-RL-v0", config=SMALL_CITY)
    env.reset(seed=2)
    world = env.unwrapped.pipeline.world
    for _ in range(30):
        expected = world.route_steer()
        env.step(1)
        assert world.ego_steer == expected
    env.close()


@pytest.mark.parametrize("env_id,actions", [
    ("DSTGrid-Occluded-v0", [0, 2, 1, 0]),  # meta-actions: once, then IDLE
    ("DSTGrid-Continuous-v0", [np.array([0.5, 0.1], np.float32),
                               np.array([-0.3, -0.2], np.float32)]),  # repeated
])
def test_action_repeat_equals_single_steps_with_the_action_held(env_id, actions):
    repeated = gym.make(env_id, config={**SMALL_CITY, "action": {"repeat": 3}})
    single = gym.make(env_id, config=SMALL_CITY)
    obs_r, info_r = repeated.reset(seed=4)
    start, steps = info_r["time"], 0
    single.reset(seed=4)
    held = repeated.unwrapped._action.held
    for a in actions:
        obs_r, reward_r, term_r, _, info_r = repeated.step(a)
        steps += 1
        total, rewards = 0.0, dict.fromkeys(info_r["rewards"], 0.0)
        for k in range(3):
            obs_s, reward_s, term_s, _, info_s = single.step(a if k == 0 else held(a))
            total += reward_s
            rewards = {n: rewards[n] + v for n, v in info_s["rewards"].items()}
            if term_s:
                break
        assert info_r["time"] == pytest.approx(info_s["time"])
        np.testing.assert_array_equal(info_r["ego_pose"], info_s["ego_pose"])
        assert reward_r == pytest.approx(total, abs=1e-12)
        assert rewards == pytest.approx(info_r["rewards"], abs=1e-12)
        assert info_r["route_progress"] == pytest.approx(info_s["route_progress"])
        for key in obs_r:
            np.testing.assert_array_equal(obs_r[key], obs_s[key])
        assert term_r == term_s
        if term_r:
            break
    if not term_r:  # each env step ran three world steps of 0.1 s
        assert info_r["time"] - start == pytest.approx(0.3 * steps)
    with pytest.raises(ConfigError, match="action.repeat: must be in"):
        gym.make(env_id, config={"action": {"repeat": 0}})
    repeated.close()
    single.close()


def test_wrapper_records_its_arguments_and_rejects_other_envs():
    from gymnasium.utils.env_checker import check_env

    base = gym.make("intersection-v2", config={"simulation_frequency": 10, "policy_frequency": 10})
    cfg = {"grid": {"height": 40, "width": 40, "cell_size": 1.0}, "lidar": {"beams": 360},
           "highway": {"resolution": 0.5}}
    env = DSTGridObservation(base, config=cfg)
    assert isinstance(env, gym.utils.RecordConstructorArgs)
    assert env._saved_kwargs == {"config": cfg}
    check_env(env, skip_render_check=True)
    with pytest.raises(TypeError, match="wraps highway-env environments.*CartPole"):
        DSTGridObservation(gym.make("CartPole-v1"))


def test_highway_slower_respects_brake_decel():
    env = gym.make("DSTGrid-Highway-v0", config={**SMALL_HIGHWAY,
                                                 "action": {"brake_decel": 2.0}})
    _, info = env.reset(seed=0)
    for _ in range(40):  # up to the top target speed
        _, _, terminated, truncated, info = env.step(2)
        assert not (terminated or truncated)
    speeds = [info["ego_speed"]]
    for t in range(15):
        _, _, terminated, _, info = env.step(0 if t < 2 else 1)
        speeds.append(info["ego_speed"])
        if terminated:
            break
    decel = -np.diff(speeds) / 0.1
    assert speeds[0] > 5.0 and decel.max() <= 2.0 + 1e-6 and decel.max() > 1.5
    env.close()


def test_action_speeds_reach_the_highway_world_and_bad_ones_are_refused():
    env = gym.make("DSTGrid-Highway-v0", config={**SMALL_HIGHWAY,
                                                 "action": {"target_speeds": [0.0, 5.0, 7.0]}})
    env.reset(seed=0)
    assert env.unwrapped.pipeline.config["highway"]["target_speeds"] == [0.0, 5.0, 7.0]
    for _ in range(60):  # FASTER to the top speed: 7 m/s, not highway-env's own 9
        _, _, terminated, truncated, info = env.step(2)
        if terminated or truncated:
            break
    assert 6.5 < info["ego_speed"] <= 7.0 + 1e-3
    bad = [({"action": {"speed_gain": 2.0}}, "action.speed_gain: the city world's"),
           ({"info": {"autopilot": True}}, "info.autopilot: highway-env's world"),
           ({"highway": {"target_speeds": [1.0]}}, "highway.target_speeds: .* at least two"),
           ({"action": {"target_speeds": [0.0, 2.0, 4.0]},
             "highway": {"target_speeds": [0.0, 3.0]}}, "differ; set one"),
           ({"source": "city", "action": {"target_speeds": [9.0, 4.5, 0.0]}}, "must increase")]
    for cfg, match in bad:  # refused when the env is made, not at its first reset
        with pytest.raises(ConfigError, match=match):
            gym.make("DSTGrid-Highway-v0", config={**SMALL_HIGHWAY, **cfg})
    # two speeds: highway-env's vehicle does not read initial_speed_index, whose default
    # (2) made any two-speed list impossible there ('must index target_speeds')
    env = gym.make("DSTGrid-Highway-v0", config={**SMALL_HIGHWAY,
                                                 "action": {"target_speeds": [0.0, 9.0]}})
    env.reset(seed=0)
    assert env.unwrapped.pipeline.config["highway"]["target_speeds"] == [0.0, 9.0]
    with pytest.raises(ConfigError, match=r"target_speeds: \[0.0, 9.0\] has no index 2 \(the "
                                          r"speed at reset, action.initial_speed_index\)"):
        gym.make("DSTGrid-RL-v0", config={"action": {"target_speeds": [0, 9]}})
    env = gym.make("DSTGrid-RL-v0", config={"grid": {"height": 36, "width": 36}, "action": {
        "target_speeds": [0, 9], "initial_speed_index": 1}})
    env.reset(seed=0)


def test_a_refused_reset_option_leaves_the_env_as_it_was():
    env = gym.make("DSTGrid-RL-v0", config={"grid": {"height": 36, "width": 36}})
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="info.autopilot"):
        env.reset(seed=0, options={"config": {"source": "highway", "info": {"autopilot": True}}})
    assert env.unwrapped.config["source"] == "city"
    env.step(1)  # the running episode goes on
    env.reset(seed=1)  # and later resets run the old configuration


def test_human_render_does_not_start_the_audio_mixer(monkeypatch):
    pygame = pytest.importorskip("pygame")
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    env = DSTGridEnv(SMALL_HIGHWAY, render_mode="human")
    env.reset(seed=0)
    assert pygame.display.get_init() and not pygame.mixer.get_init()
    env.close()


def test_info_autopilot_advises_without_changing_the_episode():
    cfg = {**SMALL_CITY, "action": {"repeat": 3}}
    plain = gym.make("DSTGrid-Occluded-v0", config=cfg)
    advised = gym.make("DSTGrid-Occluded-v0", config={**cfg, "info": {"autopilot": True}})
    o1, i1 = plain.reset(seed=4)
    o2, i2 = advised.reset(seed=4)
    assert "autopilot_action" not in i1
    actions = set()
    for _ in range(40):
        a = i2["autopilot_action"]
        assert advised.action_space.contains(a) and len(i2["autopilot_command"]) == 2
        actions.add(a)
        o1, *_, i1 = plain.step(a)
        o2, *_, i2 = advised.step(a)
        np.testing.assert_array_equal(o1["grid"], o2["grid"])
        np.testing.assert_array_equal(i1["ego_pose"], i2["ego_pose"])
    assert len(actions) >= 2
    with pytest.raises(ConfigError, match="info.autopilot"):
        gym.make("DSTGrid-v0", config={**SMALL_HIGHWAY, "info": {"autopilot": True}}).reset(seed=0)


@pytest.mark.parametrize("speed, index, accel, expected", [
    (4.5, 1, 1.44, "FASTER"),  # the autopilot speeds up gently: the next target, not IDLE
    (9.0, 2, 0.5, "IDLE"),  # at the top speed FASTER would change nothing: IDLE
    (9.0, 2, -1.0, "SLOWER"),  # it brakes: a lower target
    (0.0, 0, 0.0, "IDLE"),  # it waits at a line
    (7.0, 1, -0.3, "IDLE"),  # IDLE already brakes towards 4.5 m/s
    (0.0, 0, 1.5, "FASTER"),  # it was granted the junction
])
def test_meta_actions_imitate_the_autopilot_command(speed, index, accel, expected):
    env = gym.make("DSTGrid-Occluded-v0", config=SMALL_CITY)
    env.reset(seed=0)
    ctrl = env.unwrapped._controller
    ctrl.index = index
    env.unwrapped.pipeline.world._state["v"][-1] = speed
    assert env.unwrapped.get_action_meanings()[ctrl.imitate(accel, 0.0)] == expected
    env.close()


def test_a_missing_osm_file_is_refused_when_the_env_is_made(tmp_path, monkeypatch):
    """gym.make used to accept it; the first reset (of every env of a vector env) raised."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match=r"world\.map\.osm_file 'nosuch\.osm': no such file"):
        gym.make("DSTGrid-RL-v0", config={"world": {"map": {"kind": "osm",
                                                            "osm_file": "nosuch.osm"}}})
    # a procedural map does not read the key
    gym.make("DSTGrid-RL-v0", config={"world": {"map": {"osm_file": "nosuch.osm"}}})
