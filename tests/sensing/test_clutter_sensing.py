"""Street clutter in the sensing chain: it occludes the 2-D LIDAR when the scan plane
cuts it, is labelled non_navigable, and is absent from the GIS grid."""

from __future__ import annotations

import numpy as np

from dstenv.dst import CLASSES
from dstenv.grid import GridSpec
from dstenv.sensing import HIT_NONE, Lidar, gis_grid, label_grid
from dstenv.sensing.lidar import HIT_OBSTACLE
from dstenv.sim.types import MapClass, ObstacleKind, Obstacles

from .worlds import agents, rect_map

NONNAV, STATIC = CLASSES.index("non_navigable"), CLASSES.index("static")


def _obstacles(*rows):
    """Obstacles from ``(x, y, length, width, z_min, z_max, kind)`` tuples (yaw 0)."""
    a = np.array(rows, np.float64).reshape(-1, 7)
    return Obstacles(a[:, :2].copy(), np.zeros(len(a)), a[:, 2].copy(), a[:, 3].copy(),
                     a[:, 4].copy(), a[:, 5].copy(), a[:, 6].astype(np.uint8))


def _world(*rows):
    m = rect_map([], extent=(-20.0, 20.0, -20.0, 20.0), fill=MapClass.INTERMEDIATE)
    m.obstacles = _obstacles(*rows)
    return m


def test_a_pole_ahead_returns_its_face_and_a_crown_above_the_plane_does_not():
    # a 0.4 m box centred 5 m ahead (face at 4.8 m), a crown 10 m to the left (z 2..8)
    m = _world((5.0, 0.0, 0.4, 0.4, 0.0, 6.0, ObstacleKind.POLE),
               (0.0, 10.0, 4.0, 4.0, 2.0, 8.0, ObstacleKind.TREE_CROWN))
    lidar = Lidar({"beams": 4, "max_range": 30.0})  # back, right, forward, left
    sw = lidar.sweep(m, agents(), np.zeros(3), np.random.default_rng(0))
    np.testing.assert_allclose(sw.ranges, [30.0, 30.0, 4.8, 30.0], atol=1e-9)
    np.testing.assert_array_equal(sw.hit_id, [HIT_NONE, HIT_NONE, HIT_OBSTACLE, HIT_NONE])
    # a scan plane at 3 m cuts the crown (its near face 8 m to the left) and the pole
    high = Lidar({"beams": 4, "max_range": 30.0, "plane_height": 3.0})
    sw = high.sweep(m, agents(), np.zeros(3), np.random.default_rng(0))
    np.testing.assert_allclose(sw.ranges, [30.0, 30.0, 4.8, 8.0], atol=1e-9)


def test_an_agent_in_front_of_clutter_hides_it_and_keeps_its_index():
    m = _world((8.0, 0.0, 0.4, 0.4, 0.0, 1.0, ObstacleKind.BIN))
    lidar = Lidar({"beams": 4, "max_range": 30.0})
    sw = lidar.sweep(m, agents((4.0, 0.0, 0.0, 2.0, 1.0, 0.0)), np.zeros(3),
                     np.random.default_rng(0))
    assert sw.hit_id[2] == 0 and sw.ranges[2] == 3.0


def test_ground_clutter_is_non_navigable_under_agents_and_crowns_are_not_labelled():
    # road map; a 2 m x 1 m hedge 5 m ahead, a crown over the ego, a parked car on the hedge
    m = rect_map([], extent=(-20.0, 20.0, -20.0, 20.0), fill=MapClass.ROAD)
    m.obstacles = _obstacles((5.0, 0.0, 2.0, 1.0, 0.0, 1.2, ObstacleKind.HEDGE),
                             (0.0, 0.0, 3.0, 3.0, 2.5, 7.0, ObstacleKind.TREE_CROWN),
                             (-5.0, 0.0, 0.2, 0.2, 0.0, 0.9, ObstacleKind.BOLLARD))
    spec = GridSpec(20, 20, 1.0)  # cell (i, j) centre at x = 10 - i, y = 10 - j
    g = label_grid(m, agents(), np.zeros(3), spec)
    hedge = g[5:7, 10]  # x = 5, 4 (the box spans x 4..6, y -0.5..0.5: centres x 4, 5, 6)
    assert (hedge == NONNAV).all() and g[4, 10] == NONNAV
    assert g[10, 10] == CLASSES.index("navigable")  # under the crown: still road
    assert g[15, 10] == NONNAV  # a bollard smaller than a cell still labels its cell
    assert (g == NONNAV).sum() == 4
    with_car = label_grid(m, agents((5.0, 0.0, 0.0, 1.0, 1.0, 0.0)), np.zeros(3), spec)
    assert with_car[5, 10] == STATIC
    # the GIS grid does not know the clutter
    assert not (gis_grid(m, np.zeros(3), spec) == MapClass.INTERMEDIATE).any()


def test_generated_city_clutter_occludes_and_is_labelled():
    from dstenv.sim import World

    w = World({"traffic": {"cars": 0, "cyclists": 0, "pedestrians": 0}}, seed=2)
    assert len(w.map.obstacles) > 100
    lidar = Lidar()
    sw = lidar.sweep(w.map, w.agents, w.ego_pose, np.random.default_rng(0))
    assert (sw.hit_id == HIT_OBSTACLE).sum() > 10
    # clutter stands beside the road and the buildings: its cells are non_navigable
    from dstenv.sim.raster import lookup

    o = w.map.obstacles
    ground = o.z_min < 0.3
    assert (lookup(w.map, o.xy[ground]) == MapClass.INTERMEDIATE).all()
    spec = GridSpec(128, 128)
    labels = label_grid(w.map, w.agents, w.ego_pose, spec)
    e = _ego_frame(o.xy[ground], w.ego_pose)
    i, j = spec.to_cell(e[:, 0], e[:, 1])
    inside = (i >= 0) & (i < 128) & (j >= 0) & (j < 128)
    assert inside.sum() > 5 and (labels[i[inside], j[inside]] == NONNAV).all()


def _ego_frame(xy, pose):
    c, s = np.cos(pose[2]), np.sin(pose[2])
    d = xy - pose[:2]
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], -1)
