"""Off-street parking lots (``world.map.lot_prob``, :mod:`dstenv.sim.lots`)."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sim import World
from dstenv.sim.ego import boxes_overlap, box_corners
from dstenv.sim.raster import lookup
from dstenv.sim.types import MapClass

_QUIET = {"cars": 0, "cyclists": 0, "pedestrians": 0}


def _world(seed: int = 3, **map_kw) -> World:
    return World({"map": {"blocks_x": 4, "blocks_y": 4, "shear_deg": 0.0,
                          "bend_amplitude": 0.0, **map_kw},
                  "traffic": {"parked_density": 1.0, **_QUIET}}, seed=seed)


def test_no_lot_is_the_city_of_before_and_lots_change_only_buildings_and_cars():
    off = _world(lot_prob=0.0)
    off_other = _world(lot_prob=0.0, lot_depth=40.0, lot_fill=0.1)  # unused when off
    on = _world(lot_prob=0.6)
    assert len(off.map.meta["lot_slots"]) == 0
    for a, b in ((off, off_other), (off, on)):
        # the road network and the kerbside parking come first: the same either way
        np.testing.assert_array_equal(a.map.lanes.pts, b.map.lanes.pts)
        np.testing.assert_array_equal(a.map.meta["parking_slots"], b.map.meta["parking_slots"])
    assert len(off.map.buildings) == len(off_other.map.buildings)
    assert all(np.array_equal(p, q) for p, q in zip(off.map.buildings, off_other.map.buildings))
    assert len(on.map.meta["lot_slots"]) > 20
    assert len(on.map.buildings) < len(off.map.buildings)  # lots took their place


def test_lot_cars_stand_off_the_road_clear_of_buildings_and_each_other():
    w = _world(lot_prob=0.6)
    lots = w.map.meta["lot_slots"]
    corners = np.stack([box_corners(r[0], r[1], r[2], r[3], r[4]) for r in lots])
    # off the road, on open ground behind the sidewalk
    cls = lookup(w.map, corners.reshape(-1, 2))
    assert not np.isin(cls, [MapClass.ROAD, MapClass.BUILDING]).any()
    for i in range(len(lots)):
        assert not boxes_overlap(corners[i], np.delete(corners, i, 0)).any()
    # clutter stands clear of them (the lots are passed to its placement)
    oc = w.map.obstacles.corners()
    assert len(oc) > 0 and not any(boxes_overlap(c, oc).any() for c in corners)
    # 2-35 m from the road: distance to the nearest road cell
    road = np.argwhere(w.map.raster == MapClass.ROAD) * w.map.resolution
    d = np.array([np.min(np.hypot(*(road[:, ::-1] + np.asarray(w.map.origin) - p).T))
                  for p in lots[::7, :2]])
    assert d.min() > 2.0 and d.max() < 35.0
    # sizes from the small-car and car classes
    assert np.all((lots[:, 3] >= 3.4) & (lots[:, 3] <= 4.9) & (lots[:, 5] >= 1.4))


def test_every_lot_car_is_parked_in_the_episode():
    off, on = _world(lot_prob=0.0), _world(lot_prob=0.6)
    n_lot = len(on.map.meta["lot_slots"])
    assert on.agents.parked.sum() == off.agents.parked.sum() + n_lot
    pos = on.agents.xy[on.agents.parked]
    for p in on.map.meta["lot_slots"][:, :2]:
        assert np.min(np.hypot(*(pos - p).T)) < 1e-9


def test_lot_settings_are_validated_by_name():
    from dstenv.config import ConfigError

    with pytest.raises(ConfigError, match="lot_prob"):
        World({"map": {"lot_prob": 1.5}})
    with pytest.raises(ConfigError, match="lot_depth"):
        World({"map": {"lot_depth": 1.0}})
