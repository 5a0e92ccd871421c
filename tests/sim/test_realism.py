"""Irregular parking, vehicle sizes, pull-outs, lateral drift and clutter of the city."""

from __future__ import annotations

import numpy as np

from dstenv.sim import World, default_config
from dstenv.sim.ego import boxes_overlap
from dstenv.sim.parking import SLOT_LENGTH, VEHICLE_CLASSES, draw_vehicles, side_slots
from dstenv.sim.types import AgentKind, ObstacleKind

from .clean import clean_world

SIDE = (np.zeros(2), np.array([1.0, 0.0]), np.array([0.0, 1.0]), 200.0)


def _map_cfg(**kw):
    cfg = default_config()["map"]
    cfg.update(kw)
    return cfg


def test_lattice_slots_are_exactly_six_metres_apart_in_the_strip_middle():
    rows = side_slots(*SIDE, _map_cfg(parking_layout="lattice"), np.random.default_rng(0),
                      np.zeros((0, 2)))
    assert np.allclose(np.diff(rows[:, 0]), SLOT_LENGTH)
    assert np.allclose(rows[:, 1], 2.2 / 2) and np.allclose(np.cos(rows[:, 2]), -1.0)
    assert (rows[:, 3:] == 0).all()  # sizes drawn by the spawner


def test_irregular_slots_keep_the_drawn_gaps_and_mix_sizes():
    cfg = _map_cfg(half_on_sidewalk_prob=0.0)
    rows = side_slots(*SIDE, cfg, np.random.default_rng(1), np.zeros((0, 2)))
    x, length = rows[:, 0], rows[:, 3]
    gaps = np.diff(x) - (length[1:] + length[:-1]) / 2
    assert gaps.min() >= cfg["parking_gap_min"] - 1e-9 and gaps.max() <= cfg["parking_gap_max"]
    assert gaps.std() > 0.3 and length.std() > 0.2
    assert np.abs(np.sin(rows[:, 2])).max() > 0.01  # heading jitter
    assert np.ptp(rows[:, 1]) > 0.05  # lateral jitter


def test_draw_vehicles_stays_in_the_class_ranges():
    cls, size = draw_vehicles([1, 1, 1, 1], 400, np.random.default_rng(2))
    assert set(cls.tolist()) == {0, 1, 2, 3}
    for k, name in enumerate(VEHICLE_CLASSES):
        for d in range(3):
            lo, hi = VEHICLE_CLASSES[name][d]
            assert lo <= size[cls == k, d].min() and size[cls == k, d].max() <= hi


def test_parked_vehicles_have_the_slot_sizes_and_heights():
    w = World({"traffic": {"parked_density": 1.0, "cars": 0, "cyclists": 0, "pedestrians": 0}},
              seed=4)
    a = w.agents
    parked = a.parked
    assert parked.sum() > 50
    assert (a.length[parked] > 4.9).any() and (a.height[parked] > 2.0).any()
    assert np.all((a.height[parked] >= 1.4) & (a.height[parked] <= 3.5))
    assert (a.height[a.kind == AgentKind.PEDESTRIAN] == 1.7).all()


def test_parked_cars_pull_out_into_their_lane_without_overlaps():
    w = World({"map": {"blocks_x": 3, "blocks_y": 3},
               "traffic": {"pull_out_rate": 0.05, "parked_density": 0.8, "cars": 6,
                           "pedestrians": 0, "cyclists": 0}}, seed=3)
    start = w.agents
    for _ in range(200):
        w.step()
        a = w.agents
        c = a.corners()
        for i in range(len(a)):
            near = np.flatnonzero(np.hypot(*(a.xy - a.xy[i]).T) < 9.0)
            assert not boxes_overlap(c[i], c[near[near > i]]).any()
    a = w.agents
    left = start.parked & ~a.parked
    assert left.sum() >= 3
    assert (np.hypot(*(a.xy[left] - start.xy[left]).T) > 3.0).any()


def test_vehicles_drift_around_the_lane_centre_within_two_std():
    # (no cars pulling out of or into spaces: they move sideways at will)
    w = World({"map": {"blocks_x": 3, "blocks_y": 3},
               "traffic": {"pull_out_rate": 0.0, "pull_in_rate": 0.0}}, seed=5)
    st = w._state
    offsets = []
    for _ in range(150):
        w.step()
        # (not while double parked, changing lanes or passing: lanechange.py)
        cars = st["mobile"] & (st["akind"] == AgentKind.CAR) & (st["lc"] == 0) & ~st["hazard"]
        offsets.append(st["lat"][cars] - st["lat_goal"][cars])
    off = np.concatenate(offsets)
    drift = w.config["traffic"]["lateral_drift"]
    assert np.abs(off).max() <= 2 * drift + 1e-9 and off.std() > 0.3 * drift


def test_clutter_is_varied_seeded_and_off_in_the_clean_world():
    a = World({"map": {"blocks_x": 3, "blocks_y": 3}}, seed=6).map.obstacles
    b = World({"map": {"blocks_x": 3, "blocks_y": 3}}, seed=6).map.obstacles
    assert np.array_equal(a.xy, b.xy) and np.array_equal(a.kind, b.kind)
    kinds = set(a.kind.tolist())
    assert {ObstacleKind.POLE, ObstacleKind.TREE_TRUNK, ObstacleKind.TREE_CROWN,
            ObstacleKind.SIGN, ObstacleKind.BIN} <= kinds
    assert (a.z_max > a.z_min).all()
    crowns = a.kind == ObstacleKind.TREE_CROWN
    assert (a.z_min[crowns] >= 2.0).all()
    assert crowns.sum() == (a.kind == ObstacleKind.TREE_TRUNK).sum()
    clean = World(clean_world({"map": {"blocks_x": 3, "blocks_y": 3}}), seed=6)
    assert len(clean.map.obstacles) == 0


def test_osm_maps_get_street_clutter_beside_the_roads():
    from dstenv.scenario_files import load_scenario, scenario_path
    from dstenv.sim.raster import lookup
    from dstenv.sim.types import MapClass

    path = scenario_path("osm")
    cfg = load_scenario("osm", {"world": default_config()})["world"]
    w = World(cfg, seed=0, base_dir=path.parent)
    o = w.map.obstacles
    assert len(o) > 10 and len(w.map.streets) == len(w.map.street_lanes) > 0
    ground = o.z_min < 0.3
    assert (lookup(w.map, o.xy[ground]) == MapClass.INTERMEDIATE).all()
    again = World(cfg, seed=1, base_dir=path.parent).map.obstacles
    assert np.array_equal(o.xy, again.xy)  # fixed by the file, not the episode


def test_realism_knobs_are_validated_by_name():
    import pytest

    from dstenv.config import ConfigError

    with pytest.raises(ConfigError, match=r"world\.map\.parking_mix: must be 4 weights"):
        World({"map": {"parking_mix": [1.0, 2.0]}})
    with pytest.raises(ConfigError, match=r"world\.traffic\.vehicle_mix: must be \[\]"):
        World({"traffic": {"vehicle_mix": [0.0, 0.0, 0.0, 0.0]}})
    with pytest.raises(ConfigError, match=r"world\.clutter\.density: must be in \[0, 5\]"):
        World({"clutter": {"density": -1.0}})
    with pytest.raises(ConfigError, match=r"world\.map\.parking_layout: unknown value 'grid'"):
        World({"map": {"parking_layout": "grid"}})
