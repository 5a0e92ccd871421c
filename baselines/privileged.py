"""An asymmetric actor-critic for PPO (``ppo_grid.py --critic privileged``): the critic
reads the simulator's ground truth, the actor only the observation.

Most of the learned drivers' collisions are with cars the grid does not show yet
(occluded at a junction, ``docs/rl_collisions.py``). A critic that reads only the grid
cannot tell such a state from a safe one either, so its value, and with it every
advantage PPO follows, is blurred over both. The critic is only needed in training, so
it may read what the driver cannot (Pinto et al., "Asymmetric Actor Critic for
Image-Based Robot Learning", RSS 2018): here the ``privileged`` vector of
:class:`PrivilegedObservation`, the nearest other road users within
:data:`RADIUS` in the ego frame, occluded or not. The actor never reads it:
:class:`~extractors.GridCNN` (and so :class:`~route_features.RouteGridCNN`) skips the
key, and :class:`AsymmetricPolicy` gives the critic its own extractor
(:class:`PrivilegedCritic`: the actor's extractor class, its own weights, plus the
privileged vector). A trained policy drives on the observation alone; the evaluation env
carries the key only because the saved policy's spaces include it (its values do not
change an action, as a test checks).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import MultiInputActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

__all__ = ["AsymmetricPolicy", "AsymmetricVectorPolicy", "CRITICS", "NEAREST", "PRIVILEGED_KEY",
           "POLICIES", "PrivilegedCritic", "PrivilegedObservation", "PrivilegedVectorCritic",
           "policy_class", "privileged_features", "wrap"]

#: the observation key only the critic reads (:class:`~extractors.GridCNN` skips it)
PRIVILEGED_KEY = "privileged"
#: other road users in the vector, nearest first
NEAREST = 8
#: [m] how far the vector reaches; positions are divided by it
RADIUS = 40.0
#: [m/s] velocities are divided by it
SPEED_SCALE = 15.0


def privileged_features(ego_pose: np.ndarray, ego_speed: float, xy: np.ndarray,
                        yaw: np.ndarray, speed: np.ndarray, parked: np.ndarray,
                        nearest: int = NEAREST, radius: float = RADIUS) -> np.ndarray:
    """The ``nearest`` other road users within ``radius`` of the ego, in its frame.

    Args:
        ego_pose: ``(3,)`` ego ``(x, y, yaw)`` [m, m, rad]; ego_speed: [m/s].
        xy: ``(N, 2)`` [m], yaw: ``(N,)`` [rad], speed: ``(N,)`` [m/s], parked:
            ``(N,)`` bool: every other agent (:class:`dstenv.sim.types.Agents`).

    Returns:
        ``(nearest * 5,) float32``: per agent, nearest first, ``x / radius, y / radius``
        (x forward, y left), its velocity relative to the ego's ``(vx, vy) /``
        :data:`SPEED_SCALE` in the ego frame and a presence flag (1; parked agents 0.5);
        rows without an agent are 0.
    """
    out = np.zeros((nearest, 5), np.float32)
    if len(xy):
        c, s = np.cos(ego_pose[2]), np.sin(ego_pose[2])
        d = xy - ego_pose[:2]
        x, y = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
        dist = np.hypot(x, y)
        order = np.argsort(dist, kind="stable")
        order = order[dist[order] <= radius][:nearest]
        rel = yaw[order] - ego_pose[2]
        vx = speed[order] * np.cos(rel) - ego_speed
        vy = speed[order] * np.sin(rel)
        k = len(order)
        out[:k, 0], out[:k, 1] = x[order] / radius, y[order] / radius
        out[:k, 2], out[:k, 3] = vx / SPEED_SCALE, vy / SPEED_SCALE
        out[:k, 4] = np.where(parked[order], 0.5, 1.0)
    return out.reshape(-1)


class PrivilegedObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Adds :data:`PRIVILEGED_KEY` (:func:`privileged_features`) to a ``Dict``
    observation of a city or highway DSTGrid env."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
        space = env.observation_space
        if not isinstance(space, spaces.Dict) or PRIVILEGED_KEY in space.spaces:
            raise ValueError("PrivilegedObservation: needs a Dict observation without "
                             f"{PRIVILEGED_KEY!r} (observation.type = 'dict'), got {space}")
        self.observation_space = spaces.Dict({
            **space.spaces,
            PRIVILEGED_KEY: spaces.Box(-np.inf, np.inf, (NEAREST * 5,), np.float32)})

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        world = self.env.unwrapped.pipeline.world
        a = world.agents
        return {**observation, PRIVILEGED_KEY: privileged_features(
            world.ego_pose, world.ego_speed, a.xy, a.yaw, a.speed, a.parked)}


def wrap(env: gym.Env, critic: str) -> gym.Env:
    """``env`` itself (``critic == ""``) or with the privileged vector added."""
    if critic not in CRITICS:
        raise ValueError(f"--critic: expected one of {CRITICS}, got {critic!r}")
    return PrivilegedObservation(env) if critic else env


class PrivilegedCritic(BaseFeaturesExtractor):
    """The critic's extractor: ``base_class`` (the actor's extractor class, its own
    weights; it skips the privileged key) joined with a small MLP of the privileged
    vector.

    Args:
        observation_space: a ``Dict`` with :data:`PRIVILEGED_KEY`.
        features_dim: output size (the actor's, so that SB3's heads fit both).
        base_class, base_kwargs: the actor's extractor and its keyword arguments.
    """

    def __init__(self, observation_space: spaces.Dict, features_dim: int,
                 base_class: type[BaseFeaturesExtractor],
                 base_kwargs: dict[str, Any]) -> None:
        super().__init__(observation_space, features_dim)
        self.base = base_class(observation_space, **base_kwargs)
        n = int(np.prod(observation_space[PRIVILEGED_KEY].shape))
        self.mlp = nn.Sequential(nn.Linear(n, 64), nn.ReLU(), nn.Linear(64, 64), nn.ReLU())
        self.head = nn.Sequential(nn.Linear(self.base.features_dim + 64, features_dim),
                                  nn.ReLU())

    def forward(self, observations: Any) -> torch.Tensor:
        priv = self.mlp(observations[PRIVILEGED_KEY].float())
        return self.head(torch.cat([self.base(observations), priv], dim=1))


class AsymmetricPolicy(MultiInputActorCriticPolicy):
    """SB3's ``MultiInputPolicy`` with separate extractors: the actor's as configured
    (``features_extractor_class``), the critic's a :class:`PrivilegedCritic` around the
    same class. ``share_features_extractor`` is always ``False``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs["share_features_extractor"] = False
        super().__init__(*args, **kwargs)

    def make_features_extractor(self) -> BaseFeaturesExtractor:
        # SB3 calls this twice: first the actor's extractor, then the critic's
        if not isinstance(self._modules.get("features_extractor"), nn.Module):
            return super().make_features_extractor()
        return self.make_critic_extractor(self.features_extractor.features_dim)

    def make_critic_extractor(self, features_dim: int) -> BaseFeaturesExtractor:
        """The critic's extractor, ``features_dim`` wide (the actor's)."""
        return PrivilegedCritic(self.observation_space, features_dim,
                                self.features_extractor_class,
                                self.features_extractor_kwargs)


class PrivilegedVectorCritic(BaseFeaturesExtractor):
    """A critic's extractor without the grid: an MLP of every flat vector of the
    observation (``ego``, ``route``, :data:`PRIVILEGED_KEY`, ..., in key order).

    With the ground truth of the nearest road users (parked cars included), the ego's
    state and the route ahead, the grid adds little the value needs, and a critic
    without a CNN costs PPO almost nothing (:class:`PrivilegedCritic` runs a second
    copy of the actor's CNN).

    Args:
        observation_space: a ``Dict`` with :data:`PRIVILEGED_KEY` and a ``grid`` key
            (not read); every other entry a ``Box``.
        features_dim: output size (the actor's, so that SB3's heads fit both).
    """

    def __init__(self, observation_space: spaces.Dict, features_dim: int) -> None:
        super().__init__(observation_space, features_dim)
        self.keys = sorted(k for k in observation_space.spaces if k != "grid")
        n = sum(int(np.prod(observation_space[k].shape)) for k in self.keys)
        self.mlp = nn.Sequential(nn.Linear(n, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(),
                                 nn.Linear(256, features_dim), nn.ReLU())

    def forward(self, observations: Any) -> torch.Tensor:
        x = torch.cat([observations[k].float().flatten(1) for k in self.keys], dim=1)
        return self.mlp(x)


class AsymmetricVectorPolicy(AsymmetricPolicy):
    """:class:`AsymmetricPolicy` with a :class:`PrivilegedVectorCritic` (no grid)."""

    def make_critic_extractor(self, features_dim: int) -> BaseFeaturesExtractor:
        return PrivilegedVectorCritic(self.observation_space, features_dim)


#: the SB3 policy class of each ``--critic`` but ``''``: the actor's extractor plus the
#: vector, the vectors alone
POLICIES: dict[str, type[AsymmetricPolicy]] = {"privileged": AsymmetricPolicy,
                                               "privileged-vectors": AsymmetricVectorPolicy}
#: ``--critic`` values ('': the critic reads the actor's input)
CRITICS = ("", *POLICIES)


def policy_class(critic: str) -> type[AsymmetricPolicy]:
    """The SB3 policy class of a ``--critic`` value other than ``''``."""
    if critic not in POLICIES:
        raise ValueError(f"--critic: expected one of {tuple(POLICIES)}, got {critic!r}")
    return POLICIES[critic]


if __name__ == "__main__":
    raise SystemExit(f"{__file__}: a part of ppo_grid.py, not a script of its own; run "
                     "python baselines/ppo_grid.py --critic privileged ... (baselines/README.md)")
