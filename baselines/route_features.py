"""A feature extractor that reads the perception grid *along the route* (PPO, ``--extractor
route-cnn``).

:class:`~extractors.GridCNN` has to find on its own, in 84 x 84 cells, which few cells
lie on the route ahead, from 16 route coordinates it sees as plain numbers; a
hand-written driver (``rule_based.py``) just looks there. This extractor gives the
policy the same look without giving it anything the observation does not hold:

* the route polyline of the observation (the ego, then the K route points, in the ego
  frame) is sampled every ``spacing / per_segment`` metres (1 m by default: 40
  samples over 40 m), and at each sample at ``lateral`` offsets across the route
  (-2, -1, 0, 1, 2 m);
* the grid's channels are read there by bilinear interpolation
  (``torch.nn.functional.grid_sample``; outside the grid: 0), in the grid geometry of
  :mod:`dstenv.grid` (forward up, ego cell ``(H // 2, W // 2)``), giving a
  ``(C x lateral, samples)`` profile of the route ahead;
* two 1-D convolutions along the route read that profile, and their output joins
  :class:`~extractors.GridCNN`'s (the whole grid: cross traffic, junction corners) and
  the ``ego`` / ``route`` vectors before the last layer.

The geometry (``cell_size`` [m] and the route scale ``route_points * route_spacing``
[m], by which the observation divides route coordinates) comes from the env config.
"""

from __future__ import annotations

from typing import Any

import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn
from torch.nn import functional as F

from extractors import GridCNN

#: lateral offsets of the route profile, left positive [m]
LATERAL: tuple[float, ...] = (-2.0, -1.0, 0.0, 1.0, 2.0)


def route_sample_points(route: torch.Tensor, route_scale: float, per_segment: int,
                        lateral: tuple[float, ...]) -> torch.Tensor:
    """Ego-frame sample points along and across the route.

    Args:
        route: ``(B, 2 K)`` the observation's ``route`` (``x1, y1, ...`` divided by
            ``route_scale``).
        route_scale: [m]; per_segment: samples per route segment (the last one at
            the segment's end); lateral: offsets across the route [m].

    Returns:
        ``(B, K * per_segment, len(lateral), 2)`` points ``(x, y)`` [m].
    """
    b = route.shape[0]
    pts = route.reshape(b, -1, 2) * route_scale
    pts = torch.cat([pts.new_zeros(b, 1, 2), pts], dim=1)  # the ego first
    a, d = pts[:, :-1], pts[:, 1:] - pts[:, :-1]  # (B, K, 2) segment starts and steps
    f = torch.arange(1, per_segment + 1, dtype=route.dtype, device=route.device) / per_segment
    along = a[:, :, None] + d[:, :, None] * f[None, None, :, None]  # (B, K, S, 2)
    n = torch.stack([-d[..., 1], d[..., 0]], dim=-1)  # left normal of each segment
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    off = torch.tensor(lateral, dtype=route.dtype, device=route.device)
    p = along[:, :, :, None] + n[:, :, None, None] * off[None, None, None, :, None]
    return p.reshape(b, -1, len(lateral), 2)


def sample_grid(grid: torch.Tensor, points: torch.Tensor, cell_size: float) -> torch.Tensor:
    """Bilinear reads of ``(B, C, H, W)`` grids at ego-frame ``points (B, P, Q, 2)``
    [m]: ``(B, C, P, Q)``, 0 outside the grid (axes of :mod:`dstenv.grid`)."""
    h, w = grid.shape[-2:]
    i = h // 2 - points[..., 0] / cell_size  # row (forward is up)
    j = w // 2 - points[..., 1] / cell_size  # column (left is left)
    norm = torch.stack([2 * j / (w - 1) - 1, 2 * i / (h - 1) - 1], dim=-1)
    return F.grid_sample(grid, norm, mode="bilinear", padding_mode="zeros", align_corners=True)


class RouteGridCNN(BaseFeaturesExtractor):
    """:class:`~extractors.GridCNN` plus a 1-D CNN over the grid read along the route.

    Args:
        observation_space: a ``Dict`` with ``"grid"`` ``(C, H, W)`` and ``"route"``
            ``(2 K,)`` (and other flat vectors, e.g. ``"ego"``).
        features_dim: output size.
        cell_size: [m] of the grid; route_scale: [m] (module docstring).
        per_segment: samples per route segment.
    """

    def __init__(self, observation_space: spaces.Space, features_dim: int = 128,
                 cell_size: float = 1.0, route_scale: float = 40.0,
                 per_segment: int = 5) -> None:
        super().__init__(observation_space, features_dim)
        if (not isinstance(observation_space, spaces.Dict)
                or "route" not in observation_space.spaces):
            raise ValueError("RouteGridCNN: needs a Dict observation with 'grid' and 'route' "
                             f"(observation.type = 'dict'), got {observation_space}")
        self.cell_size, self.route_scale = float(cell_size), float(route_scale)
        self.per_segment = int(per_segment)
        self.grid_net = GridCNN(observation_space, features_dim)
        c = observation_space["grid"].shape[0]
        k = observation_space["route"].shape[0] // 2
        self.profile = nn.Sequential(
            nn.Conv1d(c * len(LATERAL), 32, 3, padding=1), nn.ReLU(),
            nn.Conv1d(32, 32, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten(),
        )
        with torch.no_grad():
            n_prof = self.profile(torch.zeros(1, c * len(LATERAL), k * self.per_segment)).shape[1]
        self.head = nn.Sequential(nn.Linear(features_dim + n_prof, features_dim), nn.ReLU())

    def route_profile(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        """``(B, C, samples, lateral)`` the grid read along the route."""
        pts = route_sample_points(observations["route"], self.route_scale, self.per_segment,
                                  LATERAL)
        return sample_grid(observations["grid"].float(), pts, self.cell_size)

    def forward(self, observations: Any) -> torch.Tensor:
        prof = self.route_profile(observations)  # (B, C, P, Q)
        b, c, p, q = prof.shape
        prof = prof.permute(0, 1, 3, 2).reshape(b, c * q, p)  # channels x lateral, along
        return self.head(torch.cat([self.grid_net(observations), self.profile(prof)], dim=1))
