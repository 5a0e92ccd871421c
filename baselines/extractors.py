"""The grid feature extractor of the PPO baselines (``ppo_grid.py --extractor grid-cnn``;
:mod:`route_features` builds on it): a small CNN for the perception grid joined with the
observation's flat vectors. Split from :mod:`ppo_grid` to keep both files small."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from privileged import PRIVILEGED_KEY

__all__ = ["GridCNN"]


class GridCNN(BaseFeaturesExtractor):
    """A small CNN for ``(C, H, W)`` perception grids, with the observation's vectors.

    A 4x4 convolution of stride 4 first cuts the grid into 4 x 4-cell patches
    (84 -> 21; cheap enough for a 2-core CPU), two 3x3 convolutions of stride 2
    follow (21 -> 11 -> 6, a cell of the last map sees ~28 cells), and a linear
    layer maps them to ``features_dim``. Float grids in [0, 1] (BetP, masses) enter
    as they are; uint8 grids are scaled to [0, 1] by stable-baselines3 first.

    Args:
        observation_space: a ``Box`` ``(C, H, W)``, or a ``Dict`` with key ``"grid"``
            (that ``Box``) and flat ``Box`` vectors (e.g. ``"ego"``) concatenated
            after the convolutions (all but :data:`privileged.PRIVILEGED_KEY`).
        features_dim: output size.
    """

    def __init__(self, observation_space: spaces.Space, features_dim: int = 256) -> None:
        super().__init__(observation_space, features_dim)
        if isinstance(observation_space, spaces.Dict):
            grid = observation_space["grid"]
            # the critic's ground truth (privileged.py) never reaches the actor
            self.vector_keys = sorted(k for k in observation_space.spaces
                                      if k not in ("grid", PRIVILEGED_KEY))
            n_vec = sum(int(np.prod(observation_space[k].shape)) for k in self.vector_keys)
        else:
            grid, self.vector_keys, n_vec = observation_space, [], 0
        if len(grid.shape) != 3 or min(grid.shape[1:]) < 16:
            raise ValueError(f"GridCNN: grid observation must be (C, H, W) with H, W >= 16, "
                             f"got {grid.shape}")
        c = grid.shape[0]
        self.cnn = nn.Sequential(
            nn.Conv2d(c, 32, 4, stride=4), nn.ReLU(),
            nn.Conv2d(32, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten(),
        )
        with torch.no_grad():
            n_flat = self.cnn(torch.zeros(1, *grid.shape)).shape[1]
        self.head = nn.Sequential(nn.Linear(n_flat + n_vec, features_dim), nn.ReLU())

    def forward(self, observations: Any) -> torch.Tensor:
        if not self.vector_keys:
            return self.head(self.cnn(observations))
        parts = [self.cnn(observations["grid"])]
        parts += [observations[k].flatten(1) for k in self.vector_keys]
        return self.head(torch.cat(parts, dim=1))
