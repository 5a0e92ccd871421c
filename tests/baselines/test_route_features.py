"""The route-profile extractor: its geometry by hand, shapes, and PPO built and reloaded
with it."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces

import ppo_grid
from route_features import LATERAL, RouteGridCNN, route_sample_points, sample_grid


def test_sample_grid_reads_cells_in_the_grid_axes() -> None:
    g = torch.zeros(1, 2, 84, 84)
    g[0, 0, 42 - 10, 42 - 2] = 1.0  # the cell 10 m ahead, 2 m left (1 m cells)
    g[0, 1, 42 + 5, 42 + 3] = 1.0  # 5 m behind, 3 m right
    pts = torch.tensor([[[[10.0, 2.0], [10.0, 0.0], [10.5, 2.0]],
                         [[-5.0, -3.0], [60.0, 0.0], [-5.0, -3.5]]]])
    out = sample_grid(g, pts, 1.0)  # (1, 2, 2, 3)
    np.testing.assert_allclose(out[0, 0, 0].numpy(), [1.0, 0.0, 0.5], atol=1e-5)  # bilinear
    np.testing.assert_allclose(out[0, 1, 1].numpy(), [1.0, 0.0, 0.5], atol=1e-5)  # outside: 0
    assert float(out[0, 1, 0].sum()) == 0.0 and float(out[0, 0, 1].sum()) == 0.0


def test_route_sample_points_along_and_across() -> None:
    # straight ahead then a left turn: (5, 0), (10, 0), then (10, 5)
    route = torch.tensor([[5.0, 0.0, 10.0, 0.0, 10.0, 5.0]]) / 15.0
    p = route_sample_points(route, 15.0, 5, LATERAL)
    assert p.shape == (1, 15, len(LATERAL), 2)
    centre = LATERAL.index(0.0)
    np.testing.assert_allclose(p[0, :5, centre].numpy(), [[1, 0], [2, 0], [3, 0], [4, 0], [5, 0]],
                               atol=1e-6)
    np.testing.assert_allclose(p[0, 4, :, 1].numpy(), LATERAL, atol=1e-6)  # left is +y
    # on the last segment (heading +y) the left normal points to -x
    np.testing.assert_allclose(p[0, 14].numpy(), [[12, 5], [11, 5], [10, 5], [9, 5], [8, 5]],
                               atol=1e-6)


def test_extractor_shapes_and_the_profile_reaches_the_output() -> None:
    space = spaces.Dict({"grid": spaces.Box(0, 255, (4, 84, 84), np.uint8),
                         "ego": spaces.Box(-1.0, 1.0, (10,), np.float32),
                         "route": spaces.Box(-1.0, 1.0, (16,), np.float32)})
    torch.manual_seed(0)
    net = RouteGridCNN(space, features_dim=32)
    route = torch.tensor([[5.0 * k, 0.0] for k in range(1, 9)]).reshape(1, 16) / 40.0
    g = torch.zeros(1, 4, 84, 84)
    obs = {"grid": g, "ego": torch.zeros(1, 10), "route": route}
    assert net(obs).shape == (1, 32)
    assert net.route_profile(obs).shape == (1, 4, 40, len(LATERAL))
    blocked = g.clone()
    blocked[0, 2, 42 - 12, 41:44] = 1.0  # a static obstacle 12 m ahead on the route
    prof = net.route_profile({**obs, "grid": blocked})
    assert float(prof[0, 2, 11, LATERAL.index(0.0)]) == pytest.approx(1.0)  # sample 12 m
    assert not torch.equal(net(obs), net({**obs, "grid": blocked}))
    with pytest.raises(ValueError, match="RouteGridCNN"):
        RouteGridCNN(spaces.Box(0, 255, (4, 84, 84), np.uint8))


def test_ppo_builds_trains_and_reloads_with_it(tmp_path, env_flags: list[str],
                                               small_config) -> None:
    import gymnasium as gym

    meta = ppo_grid.main([*env_flags, "--extractor", "route-cnn", "--n-envs", "1",
                          "--vec-env", "dummy", "--n-steps", "32", "--batch-size", "32",
                          "--n-epochs", "1", "--total-timesteps", "32", "--map-pool", "1",
                          "--verbose", "0", "--out", str(tmp_path)])
    assert meta["args"]["extractor"] == "route-cnn"
    env = gym.make("DSTGrid-Occluded-v0", config=small_config)
    model, _ = ppo_grid.load(tmp_path / "model.pt", env)
    ext = model.policy.features_extractor
    assert isinstance(ext, RouteGridCNN) and ext.cell_size == 1.0
    assert ext.route_scale == 40.0  # 8 route points 5 m apart (the env's defaults)
    saved = torch.load(tmp_path / "model.pt", weights_only=True)
    assert all(torch.equal(model.policy.state_dict()[k], saved[k]) for k in saved)
    env.close()
