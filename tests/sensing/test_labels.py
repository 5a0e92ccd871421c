"""label_grid and visible_mask: map classes, agent footprints, occluded agents."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from dstenv.dst import CLASSES
from dstenv.grid import GridSpec
from dstenv.sensing import Lidar, label_grid, visible_mask
from dstenv.sim.types import Agents, WorldMap

from .worlds import agents, rect_map

NAV, NONNAV, BUILDING, STATIC, MOVING = (
    CLASSES.index(n) for n in ("navigable", "non_navigable", "building", "static", "moving")
)
SPEC = GridSpec(16, 16, 1.0)  # ego cell (8, 8); cell (i, j) centre x = 8 - i, y = 8 - j


def test_map_classes_translate():
    # raster columns (by x): none, building, road, intermediate
    raster = np.array([[0, 1, 2, 3]], np.uint8).repeat(4, 0)
    m = WorldMap(raster, (-2.5, -2.5), 1.0)
    g = label_grid(m, Agents.empty(), np.zeros(3), GridSpec(4, 4, 1.0))
    # grid 4 x 4: cell (i, j) centre x = 2 - i -> raster column floor(x + 2.5) = 4 - i and
    # row 4 - j; column / row 4 lies outside the raster (no map -> non_navigable)
    np.testing.assert_array_equal(g[:, 1], [NONNAV, NONNAV, NAV, BUILDING])
    assert np.all(g[:, 1:] == g[:, 1:2]) and np.all(g[:, 0] == NONNAV)


def test_footprints_moving_and_static():
    m = rect_map([], extent=(-20.0, 20.0, -20.0, 20.0))
    # ego at the origin facing +y; a car 4 m ahead and 2 m left of it (world (-2, 4)),
    # heading +y too, 3 x 1.2 m: ego-frame x in [2.5, 5.5] -> rows 5, 4, 3; y = 2 -> column 6
    pose = np.array([0.0, 0.0, np.pi / 2])
    driving = agents((-2.0, 4.0, np.pi / 2, 3.0, 1.2, 5.0))
    g = label_grid(m, driving, pose, SPEC)
    expected = np.full(SPEC.shape, NAV, np.uint8)
    expected[3:6, 6] = MOVING
    np.testing.assert_array_equal(g, expected)
    stopped = agents((-2.0, 4.0, np.pi / 2, 3.0, 1.2, 0.0))
    expected[3:6, 6] = STATIC
    np.testing.assert_array_equal(label_grid(m, stopped, pose, SPEC), expected)
    # the threshold is strict: exactly 0.1 m/s is static, above is moving
    slow = agents((-2.0, 4.0, np.pi / 2, 3.0, 1.2, 0.1))
    assert label_grid(m, slow, pose, SPEC)[4, 6] == STATIC
    assert label_grid(m, slow, pose, SPEC, moving_threshold=0.05)[4, 6] == MOVING


def test_rotated_footprint_cells_are_centres_inside():
    m = rect_map([], extent=(-20.0, 20.0, -20.0, 20.0))
    box = (3.1, -1.7, 0.6, 4.5, 1.8, 3.0)
    g = label_grid(m, agents(box), np.zeros(3), GridSpec(40, 40, 0.33))
    x, y = GridSpec(40, 40, 0.33).cell_centers()
    c, s = np.cos(box[2]), np.sin(box[2])
    lx = c * (x - box[0]) + s * (y - box[1])
    ly = -s * (x - box[0]) + c * (y - box[1])
    inside = (np.abs(lx) <= 2.25) & (np.abs(ly) <= 0.9)
    np.testing.assert_array_equal(g == MOVING, inside)


def test_small_pedestrian_gets_its_centre_cell():
    m = rect_map([], extent=(-20.0, 20.0, -20.0, 20.0))
    # 0.3 x 0.3 m at ego (2.4, -0.4): no cell centre inside; its centre is in cell (6, 8)
    g = label_grid(m, agents((2.4, -0.4, 0.2, 0.3, 0.3, 1.2)), np.zeros(3), SPEC)
    assert np.count_nonzero(g == MOVING) == 1 and g[6, 8] == MOVING


def test_agent_behind_building_is_labelled_but_not_visible():
    m = rect_map([(5.2, 7.0, -6.0, 6.0)], extent=(-30.0, 30.0, -30.0, 30.0))
    hidden = (10.0, 0.0, 0.0, 4.0, 2.0, 8.0)
    seen = (0.0, 5.0, 0.0, 4.0, 2.0, 0.0)
    ag = agents(hidden, seen)
    spec = GridSpec(64, 64, 0.5)
    pose = np.zeros(3)
    labels = label_grid(m, ag, pose, spec)
    sw = Lidar().sweep(m, ag, pose, np.random.default_rng(0))
    vis = visible_mask(sw.sensor_grid(spec))
    assert vis.dtype == bool and vis.shape == spec.shape
    assert np.count_nonzero(labels == MOVING) > 0  # the hidden car is labelled
    assert not np.any(vis[labels == MOVING])  # ... and never seen
    assert np.any(vis[labels == STATIC])  # the parked one beside the ego is seen
    assert 0 not in sw.hit_id and 1 in sw.hit_id
    # the building's front face is seen, its inside is not
    assert np.any(vis[labels == BUILDING]) and not np.all(vis[labels == BUILDING])


def test_bad_raster_code_is_rejected():
    m = WorldMap(np.full((4, 4), 7, np.uint8), (-2.0, -2.0), 1.0)
    with pytest.raises(ValueError, match=r"no MapClass: \[7\]"):
        label_grid(m, Agents.empty(), np.zeros(3), GridSpec(4, 4, 1.0))


def test_sensing_never_imports_gymnasium():
    pkg = Path(__file__).resolve().parents[2] / "dstenv" / "sensing"
    for path in pkg.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            assert not any(n.split(".")[0] in ("gymnasium", "gym") for n in names), path


def test_ignore_object_edges_marks_the_occupied_rim_only():
    from dstenv.sensing.labels import ignore_object_edges

    nav, static, moving = (CLASSES.index(c) for c in ("navigable", "static", "moving"))
    building = CLASSES.index("building")
    labels = np.full((6, 7), nav, np.uint8)
    labels[2:4, 2:4] = moving  # a car of 2 x 2 cells
    labels[0, 6] = static  # a parked one in the corner
    labels[5, :] = building
    sensor = np.zeros((6, 7), np.uint8)  # unknown
    sensor[1, 1:5] = 2  # occupied row above the car: (1,1)..(1,4) touch it
    sensor[2, 4] = 2  # beside it
    sensor[2, 2] = 2  # on the car itself: stays moving
    sensor[0, 0] = 2  # occupied, far from any object: stays navigable
    sensor[1, 5] = 2  # touches the corner car at (0, 6)
    sensor[4, 1:5] = 1  # free below the car: stays navigable
    sensor[5, 3] = 2  # a building hit: no object among its neighbours
    want = labels.copy()
    for i, j in [(1, 1), (1, 2), (1, 3), (1, 4), (2, 4), (1, 5)]:
        want[i, j] = 255
    assert ignore_object_edges(labels, sensor, 255) == 6
    np.testing.assert_array_equal(labels, want)
    with pytest.raises(ValueError, match="differ in shape"):
        ignore_object_edges(labels, sensor[:3], 255)
