"""The asymmetric actor-critic (``ppo_grid.py --critic privileged``): the ground-truth
vector, an actor that cannot read it, a critic that does, DAgger and PPO on it, and
evaluation of the saved policy."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import ppo_grid
from conftest import TINY_WARM
from imitation import _fit
from ppo_grid import Args, build_model, make_vec_env
from privileged import (NEAREST, PRIVILEGED_KEY, RADIUS, SPEED_SCALE, AsymmetricPolicy,
                        AsymmetricVectorPolicy, PrivilegedCritic, PrivilegedVectorCritic,
                        privileged_features)
from rl_common import parse_args


def test_features_in_the_ego_frame_nearest_first() -> None:
    # the ego at (10, 0) heading +y (north) at 5 m/s
    ego, v = np.array([10.0, 0.0, np.pi / 2]), 5.0
    xy = np.array([[10.0, 20.0],  # 20 m ahead, driving west at 3 m/s
                   [5.0, 0.0],  # 5 m to its left, parked
                   [10.0, 45.0],  # beyond the radius
                   [13.0, 0.0]])  # 3 m to its right, heading north at 5 m/s: level
    yaw = np.array([np.pi, 0.0, 0.0, np.pi / 2])
    speed = np.array([3.0, 0.0, 1.0, 5.0])
    parked = np.array([False, True, False, False])
    f = privileged_features(ego, v, xy, yaw, speed, parked).reshape(NEAREST, 5)
    np.testing.assert_allclose(f[0], [0, -3 / RADIUS, 0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(f[1], [0, 5 / RADIUS, -5 / SPEED_SCALE, 0, 0.5], atol=1e-6)
    # heading west is +90 deg from north: to the ego's left; it closes at -5 m/s along
    np.testing.assert_allclose(f[2], [20 / RADIUS, 0, -5 / SPEED_SCALE, 3 / SPEED_SCALE, 1],
                               atol=1e-6)
    assert not f[3:].any()  # the fourth is 45 m away
    assert privileged_features(ego, v, np.zeros((0, 2)), *(np.zeros(0),) * 2,
                               np.zeros(0, bool)).shape == (NEAREST * 5,)


#: each ``--critic`` and the extractor class of its critic
CRITIC_CLASSES = {"privileged": PrivilegedCritic, "privileged-vectors": PrivilegedVectorCritic}


@pytest.fixture(params=sorted(CRITIC_CLASSES))
def asym(env_flags: list[str], request):
    args = parse_args(Args, [*env_flags, "--n-envs", "1", "--vec-env", "dummy", "--extractor",
                             "route-cnn", "--critic", request.param])
    env = make_vec_env(args)
    try:
        yield build_model(args, env), env
    finally:
        env.close()


def test_the_actor_never_reads_the_ground_truth(asym) -> None:
    model, env = asym
    policy = model.policy
    assert isinstance(policy, AsymmetricPolicy)
    critic = type(policy.vf_features_extractor)
    assert critic in CRITIC_CLASSES.values()
    assert isinstance(policy, AsymmetricVectorPolicy) == (critic is PrivilegedVectorCritic)
    assert not isinstance(policy.pi_features_extractor, tuple(CRITIC_CLASSES.values()))
    obs = env.reset()
    assert obs[PRIVILEGED_KEY].shape == (1, NEAREST * 5) and obs[PRIVILEGED_KEY].any()
    other = {**obs, PRIVILEGED_KEY: np.random.default_rng(0).uniform(
        -1, 1, obs[PRIVILEGED_KEY].shape).astype(np.float32)}
    with torch.no_grad():
        t, _ = policy.obs_to_tensor(obs)
        u, _ = policy.obs_to_tensor(other)
        logits = [policy.get_distribution(o).distribution.logits for o in (t, u)]
        values = [policy.predict_values(o) for o in (t, u)]
    assert torch.equal(logits[0], logits[1])
    assert not torch.equal(values[0], values[1])  # the critic does read it


@pytest.mark.parametrize("asym", ["privileged-vectors"], indirect=True)
def test_the_vector_critic_never_reads_the_grid(asym) -> None:
    model, env = asym
    policy = model.policy
    obs = env.reset()
    assert isinstance(policy.vf_features_extractor, PrivilegedVectorCritic)
    assert PRIVILEGED_KEY in policy.vf_features_extractor.keys
    other = {**obs, "grid": 255 - obs["grid"]}
    moved = {**obs, "ego": obs["ego"] + 0.5}
    with torch.no_grad():
        v = [policy.predict_values(policy.obs_to_tensor(o)[0]) for o in (obs, other, moved)]
    assert torch.equal(v[0], v[1]) and not torch.equal(v[0], v[2])


def test_dagger_value_fit_trains_the_critics_own_extractor(asym) -> None:
    model, env = asym
    policy = model.policy
    space = env.observation_space
    rng = np.random.default_rng(0)
    n = 200
    # everything the actor sees is the same in every sample; the returns follow the
    # privileged vector alone, so only a critic that reads it can fit them
    data = {k: np.full((n, *space[k].shape), 0.5, space[k].dtype) for k in space.spaces
            if k not in ("grid", PRIVILEGED_KEY)}
    data["grid"] = np.zeros((n, *space["grid"].shape), np.uint8)
    data[PRIVILEGED_KEY] = np.zeros((n, NEAREST * 5), np.float32)
    data[PRIVILEGED_KEY][:, 0] = rng.uniform(-1, 1, n)  # the nearest road user's x
    data["label"] = rng.integers(0, model.action_space.n, n)
    returns = (5 * data[PRIVILEGED_KEY][:, 0]).astype(np.float32)
    critic0 = [p.detach().clone() for p in policy.vf_features_extractor.mlp.parameters()]
    stats = _fit(model, data, returns, 40, 1e-3, 50, rng)
    assert all(not torch.equal(a, b) for a, b in
               zip(critic0, policy.vf_features_extractor.mlp.parameters()))
    assert stats["value_rmse"] < 0.5 * float(np.std(returns))


@pytest.mark.parametrize("critic", sorted(CRITIC_CLASSES))
def test_run_saves_a_policy_that_evaluate_scores(env_flags: list[str], tmp_path,
                                                  critic: str) -> None:
    from evaluate import PPOPolicy
    from rl_common import EnvArgs

    out = tmp_path / "asym"
    meta = ppo_grid.main([*env_flags, *TINY_WARM, "--n-epochs", "1", "--total-timesteps", "184",
                          "--extractor", "route-cnn", "--critic", critic,
                          "--anchor", "--ent-coef", "0.1", "--checkpoint-every", "0",
                          "--out", str(out)])
    assert meta["timesteps"] == 64 and PRIVILEGED_KEY in meta["observation_space"]
    policy = PPOPolicy(str(out / "model.pt"))
    env = policy.make_env(parse_args(EnvArgs, env_flags))
    try:
        obs, info = env.reset(seed=3)
        assert PRIVILEGED_KEY in obs
        policy.reset(env, 3)
        assert env.action_space.contains(policy.act(obs, info))
    finally:
        env.close()


def test_privileged_critic_needs_a_grid_extractor(env_flags: list[str]) -> None:
    args = parse_args(Args, [*env_flags, "--n-envs", "1", "--vec-env", "dummy", "--extractor",
                             "combined", "--critic", "privileged"])
    env = make_vec_env(args)
    try:
        with pytest.raises(ValueError, match="--critic privileged"):
            build_model(args, env)
    finally:
        env.close()
    with pytest.raises(ValueError, match="--critic: expected"):
        ppo_grid.main([*env_flags, "--critic", "oracle", "--out", "unused"])
    from privileged import policy_class
    with pytest.raises(ValueError, match="--critic: expected one of"):
        policy_class("")
