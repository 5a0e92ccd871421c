"""DSTGridEnv behaviour: determinism, pickling, vector envs, config, episode end, info."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

import dstenv  # noqa: F401
from dstenv.config import ConfigError
from dstenv.envs import DSTGridEnv

from .conftest import SMALL_CITY, SMALL_HIGHWAY


def _assert_same(a, b, where=""):
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _assert_same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, np.ndarray):
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), where
    else:
        assert a == b, where


def _rollout(config, seed, steps, id_="DSTGrid-RL-v0"):
    env = gym.make(id_, config=config)
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(int(rng.integers(env.action_space.n)))
        out.append((obs, {**info, "reward": r}))
        if term or trunc:
            obs, info = env.reset()
            out.append((obs, info))
    return out


@pytest.mark.parametrize("config,id_", [
    (SMALL_HIGHWAY, "DSTGrid-Highway-v0"),
    pytest.param(SMALL_CITY, "DSTGrid-RL-v0"),
])
def test_same_seed_same_observations_and_infos_over_100_steps(config, id_):
    cfg = {**config, "info": {"lidar_points": True}}
    a = _rollout(cfg, 11, 100, id_)
    b = _rollout(cfg, 11, 100, id_)
    assert len(a) == len(b)
    for i, ((oa, ia), (ob, ib)) in enumerate(zip(a, b)):
        _assert_same(oa, ob, f"obs at step {i}")
        _assert_same(ia, ib, f"step {i}")
    c = _rollout(cfg, 12, 5, id_)
    grid = lambda o: o["grid"] if isinstance(o, dict) else o  # noqa: E731
    assert not np.array_equal(grid(a[5][0]), grid(c[5][0]))


@pytest.mark.parametrize("config,id_", [
    (SMALL_HIGHWAY, "DSTGrid-Highway-v0"),
    pytest.param(SMALL_CITY, "DSTGrid-RL-v0"),
])
def test_pickled_env_continues_identically(config, id_):
    env = gym.make(id_, config=config)
    env.reset(seed=3)
    for _ in range(3):
        env.step(1)
    clone = pickle.loads(pickle.dumps(env))
    for action in (2, 1, 0, 1, 2):
        oa, ra, *_ = env.step(action)
        ob, rb, *_ = clone.step(action)
        _assert_same(oa, ob, "obs")
        assert ra == rb


def _make_highway():
    return gym.make("DSTGrid-Highway-v0", config=SMALL_HIGHWAY)


def test_labels_in_info_are_opt_in_and_change_nothing_else():
    # default: no ground truth computed or returned; info.labels adds it, and the
    # observations and every other info entry stay bit-identical
    plain = _rollout(SMALL_CITY, 3, 12)
    full = _rollout({**SMALL_CITY, "info": {"labels": True}}, 3, 12)
    for (oa, ia), (ob, ib) in zip(plain, full):
        assert "labels" not in ia and "visible" not in ia
        assert ib["labels"].shape == ib["visible"].shape == ib["sensor"].shape
        assert ib["labels"].dtype == np.uint8 and ib["visible"].dtype == bool
        assert np.array_equal(ib["visible"], ib["sensor"] != 0)
        _assert_same(oa, ob)
        _assert_same(ia, {k: v for k, v in ib.items() if k not in ("labels", "visible")})


def test_sync_vector_env():
    venv = gym.vector.SyncVectorEnv([_make_highway, _make_highway])
    obs, info = venv.reset(seed=[1, 2])
    assert obs.shape == (2, 4, 40, 40) and info["sensor"].shape == (2, 40, 40)
    for _ in range(3):
        obs, rew, term, trunc, info = venv.step(np.array([1, 2]))
    assert rew.shape == (2,) and info["rewards"]["progress"].shape == (2,)
    venv.close()


def test_async_vector_env():
    venv = gym.vector.AsyncVectorEnv([_make_highway, _make_highway])
    obs, _ = venv.reset(seed=[1, 2])
    single = gym.make("DSTGrid-Highway-v0", config=SMALL_HIGHWAY)
    ref, _ = single.reset(seed=2)
    assert np.array_equal(obs[1], ref)  # each sub-env seeded like a single env
    obs, rew, *_ = venv.step(np.array([1, 1]))
    assert obs.shape == (2, 4, 40, 40)
    venv.close()


@pytest.mark.parametrize("mode,shape,dtype", [
    ("pignistic", (5, 40, 40), np.float32), ("fcn10", (10, 40, 40), np.float32),
    ("masses", (32, 40, 40), np.float32), ("image", (4, 40, 40), np.uint8)])
def test_observation_modes_via_config(mode, shape, dtype):
    env = DSTGridEnv({**SMALL_HIGHWAY, "observation": {"type": mode}})
    obs, _ = env.reset(seed=0)
    assert obs.shape == shape and obs.dtype == dtype and env.observation_space.contains(obs)
    obs, *_ = env.step(1)
    assert env.observation_space.contains(obs)
    if mode == "masses":  # masses are a distribution per cell
        assert np.allclose(obs.sum(axis=0), 1.0, atol=1e-5)


def test_reset_options_config_keeps_spaces_fixed():
    env = DSTGridEnv(SMALL_HIGHWAY)
    env.reset(seed=0)
    obs, _ = env.reset(seed=0, options={"config": {"lidar": {"beams": 180}}})
    assert obs.shape == (4, 40, 40) and env.pipeline.config["lidar"]["beams"] == 180
    # a new grid shape would break vector envs and policies: a clear error instead
    with pytest.raises(ConfigError, match=r"alters the observation or action space .*"
                                          r"build a new env with gym.make"):
        env.reset(seed=0, options={"config": {"grid": {"height": 48, "width": 44}}})
    with pytest.raises(ConfigError, match="unknown key 'colour'"):
        env.reset(options={"config": {"observation": {"colour": 1}}})
    for bad in ({"cfg": {}}, "config", [{"config": {}}]):  # a list was 'unhashable type'
        with pytest.raises(ConfigError, match="reset options: a dict of the one key 'config'"):
            env.reset(options=bad)


def test_bad_config_names_the_key():
    msg = "config.grid.heigth: unknown key 'heigth'; allowed keys: cell_size, height, width"
    with pytest.raises(ConfigError, match=msg):
        DSTGridEnv({"grid": {"heigth": 10}})
    with pytest.raises(ConfigError, match="unknown mode 'rgb'"):
        DSTGridEnv({**SMALL_HIGHWAY, "observation": {"type": "rgb"}})


def test_collision_terminates_with_penalty_and_info_is_complete():
    env = DSTGridEnv({**SMALL_HIGHWAY, "info": {"lidar_points": True, "labels": True}})
    env.reset(seed=0)
    for _ in range(300):  # full speed through the busy junction, never braking
        obs, reward, term, trunc, info = env.step(2)
        if term:
            break
    assert term and (info["collision"] or info["off_road"] or info["arrived"])
    assert reward == pytest.approx(sum(info["rewards"].values()))
    if info["collision"]:
        assert info["rewards"]["collision"] == -10.0
    for key, shape, dtype in [("labels", (40, 40), np.uint8), ("visible", (40, 40), bool),
                              ("sensor", (40, 40), np.uint8), ("gis", (40, 40), np.uint8),
                              ("ego_pose", (3,), np.float64),
                              ("lidar_points", (360, 2), np.float32)]:
        assert info[key].shape == shape and info[key].dtype == dtype, key
    assert np.array_equal(info["visible"], info["sensor"] != 0)
    # a step after the end went on simulating and charged the penalty again (attack 14)
    pose = info["ego_pose"].copy()
    with pytest.raises(RuntimeError, match=rf"the episode has ended \({info['termination_reason']}"
                                           r", terminated=True\); call reset\(\) first"):
        env.step(2)
    assert np.array_equal(env.unwrapped.pipeline.world.ego_pose, pose)  # nothing moved
    env.reset(seed=1)
    env.step(1)  # a new episode steps again


def test_continuous_actions_on_highway_scene():
    env = DSTGridEnv({**SMALL_HIGHWAY, "action": {"type": "continuous"}})
    assert env.action_space.shape == (2,) and env.action_space.dtype == np.float32
    env.reset(seed=0)
    v0 = env.unwrapped.pipeline.world.ego_speed
    for _ in range(5):
        _, _, _, _, info = env.step(np.array([-1.0, 0.0], np.float32))  # full brake
    assert info["ego_speed"] == pytest.approx(v0 - 5 * 0.1 * 3.0, abs=1e-6)


def test_render_rgb_array():
    env = gym.make("DSTGrid-Highway-v0", config=SMALL_HIGHWAY, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(1)
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3 and img.std() > 10


def test_human_render_mode_runs_headless(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    env = DSTGridEnv(SMALL_HIGHWAY, render_mode="human")
    env.reset(seed=0)
    assert env.render() is None and env._window is not None
    env.step(1)
    clone = pickle.loads(pickle.dumps(env))  # the window is dropped, not pickled
    assert clone._window is None
    env.close()
    assert env._window is None


def test_city_turn_meta_actions_steer_the_route():
    import gymnasium as gym

    from dstenv.sim.lanes import LaneKind, Turn

    env = gym.make("DSTGrid-v0", config=SMALL_CITY)
    assert env.action_space.n == 5
    env.reset(seed=2)
    world = env.unwrapped.pipeline.world
    net = world.map.lanes
    turned = 0
    for t in range(60):
        action = 3 if t % 2 else 4  # LEFT, RIGHT alternately: the last valid one wins
        env.step(action)
        route = world.route
        if net.kind[route[0]] != LaneKind.CONNECTOR:
            k = next((i for i in range(1, len(route))
                      if net.kind[route[i]] == LaneKind.CONNECTOR), None)
            turned += k is not None and net.turn[route[k]] in (Turn.LEFT, Turn.RIGHT)
    env.close()
    assert turned > 0
    speed_only = gym.make("DSTGrid-v0", config={**SMALL_CITY, "action": {"type": "speed"}})
    assert speed_only.action_space.n == 3
    speed_only.close()


def test_an_action_outside_the_space_is_refused_in_one_line():
    # -1 used to be taken as the last action, 99 to raise an IndexError
    env = gym.make("DSTGrid-RL-v0")
    env.reset(seed=0)
    for bad in (-1, 99, 1.5, True, "FASTER"):
        with pytest.raises(ValueError, match=r"action .* is not in Discrete"):
            env.step(bad)
    for good in (1, np.int64(2), np.array(0)):
        env.step(good)
    env.close()


def test_wrong_argument_kinds_are_named():
    """Attack 14: scenario=3 was a TypeError from pathlib, world='city' passed until the
    first reset, a complex action ran on its real part with a ComplexWarning."""
    with pytest.raises(ConfigError, match="scenario: a shipped name or a .toml path, got int 3"):
        DSTGridEnv(scenario=3)
    with pytest.raises(ConfigError, match=r"e\.g\. \./my_scenario\.toml"):
        DSTGridEnv(scenario=".")
    with pytest.raises(TypeError, match=r"world: a world source object .* got 'city'; to pick "
                                        r"one by name use config=\{'source': \.\.\.\}"):
        DSTGridEnv(world="city")
    env = DSTGridEnv({**SMALL_HIGHWAY, "action": {"type": "continuous"}})
    env.reset(seed=0)
    for bad in (np.array([0.5 + 1j, 0.0]), np.array(["a", "b"])):
        with pytest.raises(ValueError, match="expected 2 real numbers"):
            env.step(bad)
    env.step(np.array([True, False]))  # bools and ints are numbers


def test_a_first_reset_refused_for_its_options_leaves_a_usable_env():
    """Attack 18: gymnasium's passive checker marked the first reset checked before it
    ran, so after a refused one every step failed ('cannot unpack non-iterable NoneType')."""
    import gymnasium as gym

    env = gym.make("DSTGrid-Highway-v0", config={"grid": {"height": 40, "width": 40}})
    with pytest.raises(ConfigError, match="reset options: a dict of the one key 'config'"):
        env.reset(seed=1, options={"bogus": 1})
    env.reset(seed=1)
    obs, reward, *_ = env.step(1)
    assert env.observation_space.contains(obs) and np.isfinite(reward)
    env.close()
