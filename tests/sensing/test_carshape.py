"""Cars as a body on wheels (``lidar.hdl64.vehicle_shape = "car"``): what the beams meet."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.sensing import carshape as cs
from dstenv.sensing.lidar3d import SURFACES, Hdl64
from dstenv.sensing.scene3d import box_table
from dstenv.sim.types import AgentKind

from .worlds import agents, rect_map

H = 1.73
IDEAL = {"range_noise": 0.0, "dropout": 0.0, "intensity_noise": 0.0, "spin_rate": 0.0,
         "min_range": 0.0}
AGENT = SURFACES.index("agent")
ROAD = SURFACES.index("road")


def _sweep(shape, ag, **kw):
    lidar = Hdl64({"model": "hdl64", "hdl64": {**IDEAL, "vehicle_shape": shape, **kw}})
    return lidar.sweep(rect_map([]), ag, np.zeros(3), np.random.default_rng(0))


def _car():  # faces x = 8..12, y = -1..1, 1.5 m tall (a car: it has a cabin)
    return agents((10.0, 0.0, 0.0, 4.0, 2.0, 0.0))


def test_box_table_rows_and_default_is_the_prism():
    ag = agents((10.0, 0.0, 0.0, 4.0, 2.0, 0.0), (0.0, 10.0, 0.5, 4.5, 1.8, 3.0))
    ag.kind[1] = AgentKind.CYCLIST
    clutter = np.zeros((3, 11))
    clutter[:, 9] = np.arange(3)
    prisms = box_table(ag, clutter)
    shaped = box_table(ag, clutter, car_shape=True)
    assert prisms.shape == (5, 11) and shaped.shape == (5 + 4, 11)  # one car: 4 parts more
    assert np.array_equal(shaped[1:5], prisms[1:5])  # the cyclist and the clutter as before
    # row 0 stays the car's: its long lower box, narrower by the corner cut, on the sills
    assert shaped[0, 5] == pytest.approx(1.0 - cs.CORNER_Y)
    assert shaped[0, 6] == pytest.approx(cs.CLEARANCE)
    assert shaped[0, 7] == pytest.approx(cs.BELT * 1.5)
    assert np.all(shaped[5:, 9] == 0) and np.all(shaped[5:, 8] == AGENT)
    wide, cabin, axle_a, axle_b = shaped[5:]
    assert wide[4] == pytest.approx(2.0 - cs.CORNER_X) and wide[5] == pytest.approx(1.0)
    assert cabin[6] == pytest.approx(cs.BELT * 1.5) and cabin[7] == pytest.approx(1.5)
    assert cabin[5] == pytest.approx(1.0 - cs.TUMBLEHOME)
    assert axle_a[6] == 0.0 and axle_a[7] == pytest.approx(cs.CLEARANCE)
    assert sorted([axle_a[0], axle_b[0]]) == pytest.approx([10.0 - 1.15, 10.0 + 1.15])
    # the default section keeps the prism
    default = Hdl64({"model": "hdl64"})
    assert default.config["vehicle_shape"] == "box"


def test_a_van_has_no_cabin_and_keeps_its_roof():
    ag = agents((10.0, 0.0, 0.0, 5.5, 2.1, 0.0))
    ag.height[:] = 2.6
    t = box_table(ag, np.zeros((0, 11)), car_shape=True)
    assert t[0, 7] == pytest.approx(2.6) and t[1, 7] == pytest.approx(2.6)
    assert t[2, 6] == t[2, 7] == pytest.approx(2.6)  # the empty cabin: zero height


def test_beams_meet_the_body_not_a_prism():
    box = _sweep("box", _car(), channels=64, azimuth_step=0.25)
    car = _sweep("car", _car(), channels=64, azimuth_step=0.25)
    p, on = car.points, car.surface == AGENT
    z = p[:, 2] + H  # height above the road
    assert on.sum() > 50
    assert np.all(car.index[on] == 0)
    # nothing on the body below the sills but the wheels, near the two axles
    low = on & (z < cs.CLEARANCE - 1e-4)
    ax = np.array([10.0 - 1.15, 10.0 + 1.15])
    near_axle = np.min(np.abs(p[:, 0, None] - ax[None, :]), axis=1) <= cs.WHEEL_HALF_LENGTH + 1e-4
    assert low.any() and np.all(near_axle[low])
    # the cut corners: no return in the corner squares of the footprint
    corner = (p[:, 0] < 8.0 + cs.CORNER_X - 1e-3) & (np.abs(p[:, 1]) > 1.0 - cs.CORNER_Y + 1e-3)
    assert not (on & corner).any()
    assert (box.surface == AGENT)[(box.points[:, 0] < 8.0 + cs.CORNER_X - 1e-3)
                                  & (np.abs(box.points[:, 1]) > 1.0 - cs.CORNER_Y + 1e-3)].any()
    # above the belt line only the cabin: narrower, and no higher than the roof
    upper = on & (z > cs.BELT * 1.5 + 1e-4)
    assert upper.any() and np.all(np.abs(p[upper, 1]) <= 1.0 - cs.TUMBLEHOME + 1e-4)
    assert np.all(z[on] <= 1.5 + 1e-4)
    # a beam that passes under the sills meets the road beneath the car, inside its footprint
    under = (car.surface == ROAD) & (p[:, 0] > 8.0) & (p[:, 0] < 12.0) & (np.abs(p[:, 1]) < 0.8)
    assert under.any()
    assert not ((box.surface == ROAD) & (box.points[:, 0] > 8.0) & (box.points[:, 0] < 12.0)
                & (np.abs(box.points[:, 1]) < 0.8)).any()


def test_cyclists_and_pedestrians_stay_prisms():
    ag = agents((10.0, 0.0, 0.0, 1.8, 0.6, 0.0))
    ag.kind[:] = AgentKind.CYCLIST
    ag.height[:] = 1.7
    box = _sweep("box", ag, channels=32, azimuth_step=0.5)
    car = _sweep("car", ag, channels=32, azimuth_step=0.5)
    assert np.array_equal(box.points, car.points) and np.array_equal(box.surface, car.surface)


def test_bad_vehicle_shape_is_named():
    with pytest.raises(ConfigError, match="vehicle_shape"):
        Hdl64({"model": "hdl64", "hdl64": {"vehicle_shape": "sphere"}})
