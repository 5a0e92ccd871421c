"""The occluder-height contract of dstenv.sim.types (agents, buildings, clutter, kerb)."""

import numpy as np
import pytest

from dstenv.sim.osm_xml import building_height
from dstenv.sim.types import (
    AGENT_HEIGHT,
    DEFAULT_BUILDING_HEIGHT,
    AgentKind,
    Agents,
    MapClass,
    ObstacleKind,
    Obstacles,
    WorldMap,
)


def test_agent_height_defaults_to_the_kind_table():
    kind = np.array([AgentKind.CAR, AgentKind.PEDESTRIAN, AgentKind.CYCLIST], np.uint8)
    a = Agents(np.zeros((3, 2)), np.zeros(3), np.zeros(3), np.ones(3), np.ones(3), kind,
               np.zeros(3, bool))
    assert a.height.tolist() == [1.5, 1.7, 1.7]
    assert AGENT_HEIGHT[AgentKind.CAR] == 1.5
    assert Agents.empty().height.shape == (0,)


def test_building_heights_default_and_shape_check():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    m = WorldMap(np.zeros((2, 2), np.uint8), (0.0, 0.0), 1.0, [sq, sq + 2])
    assert m.building_heights.tolist() == [DEFAULT_BUILDING_HEIGHT] * 2
    assert len(m.obstacles) == 0
    with pytest.raises(ValueError, match="building_heights"):
        WorldMap(np.zeros((2, 2), np.uint8), (0.0, 0.0), 1.0, [sq], building_heights=[3.0, 4.0])


def test_ground_height_raises_intermediate_cells_by_the_kerb():
    raster = np.array([[MapClass.ROAD, MapClass.INTERMEDIATE],
                       [MapClass.BUILDING, MapClass.NONE]], np.uint8)
    m = WorldMap(raster, (10.0, 20.0), 2.0, kerb_height=0.15)
    pts = np.array([[11.0, 21.0], [13.0, 21.0], [11.0, 23.0], [13.0, 23.0], [0.0, 0.0]])
    assert m.ground_height(pts).tolist() == [0.0, 0.15, 0.0, 0.0, 0.0]


def test_obstacle_corners_and_plane_cut():
    obs = Obstacles(np.array([[1.0, 2.0], [0.0, 0.0]]), np.array([np.pi / 2, 0.0]),
                    np.array([4.0, 0.3]), np.array([2.0, 0.3]), np.array([0.0, 2.0]),
                    np.array([1.0, 8.0]),
                    np.array([ObstacleKind.HEDGE, ObstacleKind.TREE_CROWN], np.uint8))
    c = obs.corners()
    assert c.shape == (2, 4, 2)
    # a 4 x 2 box turned by 90 deg spans x 0..2 and y 0..4
    np.testing.assert_allclose(c[0].min(0), [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(c[0].max(0), [2.0, 4.0], atol=1e-12)
    assert obs.at_height(0.5).tolist() == [True, False]
    assert obs.at_height(3.0).tolist() == [False, True]
    assert len(Obstacles.empty()) == 0


def test_osm_building_height_tags():
    assert building_height({"height": "12.5 m"}) == 12.5
    assert building_height({"building:levels": "4", "roof:levels": "1"}) == 15.0
    assert building_height({"building": "yes"}) == DEFAULT_BUILDING_HEIGHT
    assert building_height({"height": "tall"}) == DEFAULT_BUILDING_HEIGHT


def test_generated_city_has_building_heights_in_range():
    from dstenv.sim import World

    w = World(seed=3)
    h = w.map.building_heights
    assert h.shape == (len(w.map.buildings),) and len(h) > 10
    assert h.min() >= 6.0 and h.max() <= 30.0 and h.std() > 1.0
    assert w.map.kerb_height == 0.12
