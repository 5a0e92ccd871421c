"""Cars pulling into kerbside spaces (``dstenv/sim/pullin.py``), moving -> static."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.dst import CLASSES
from dstenv.grid import GridSpec
from dstenv.sensing import label_grid
from dstenv.sim import World, agenttable, pullin
from dstenv.sim.ego import box_corners, boxes_overlap
from dstenv.sim.lanes import Control
from dstenv.sim.raster import lookup
from dstenv.sim.traffic import PARK_DECEL

from .numerics import numpy_math_is_libm
from dstenv.sim.types import AgentKind, MapClass, Obstacles

from .handmade import LW, TRIM, cross_map, lane_ending_near, lane_starting_near

QUIET = {"traffic": {"cars": 0, "cyclists": 0, "pedestrians": 0, "halt_rate": 0.0,
                     "pause_rate": 0.0, "lane_change_rate": 0.0, "lateral_drift": 0.0,
                     "pull_out_rate": 0.0, "pull_in_rate": 1e-4, "parked_density": 0.0,
                     "double_park_prob": 0.0}}
STRIP = 2.2  # [m] kerb strip east of the south arm's northbound lane: x in [LW, LW + STRIP]
SLOT_Y = np.arange(-55.0, -12.0, 6.0)  # slot centres along it (northbound: yaw pi/2)
HOLD = (0.0, 0.0)
BUSY = {"map": {"blocks_x": 3, "blocks_y": 3},
        "traffic": {"pull_in_rate": 0.1, "parked_density": 0.3, "pull_out_rate": 0.0}}


def _world(parked_at=(-43.0, -19.0, -13.0)):
    """The one-lane cross with a parking strip along the south arm (slots every 6 m)
    and parked cars (4.5 x 1.8 m) at ``parked_at``; the ego stands on the west arm."""
    m = cross_map(Control.STOP, 1)
    m.meta["parking_slots"] = np.array([[LW + STRIP / 2, y, np.pi / 2, 0.0, 0.0, 0.0]
                                        for y in SLOT_Y])
    w = World(QUIET, seed=0, world_map=m)
    net = w.map.lanes
    w.place_ego(lane_starting_near(net, -TRIM, LW / 2), 30.0)
    st = w._state
    for y in parked_at:
        agenttable.add_row(st, AgentKind.CAR, (LW + STRIP / 2, y), np.pi / 2, 4.5, 1.8, parked=True,
                      at=len(st["v"]) - 1)
    return w, lane_ending_near(net, LW / 2, -TRIM)


def _overlaps(w):
    a = w.agents
    c = np.concatenate([a.corners(), box_corners(*w.ego_pose, *w.ego_size)[None]])
    return sum(int(boxes_overlap(c[i], c[i + 1:]).any()) for i in range(len(c) - 1))


def test_space_is_the_nearest_free_slot_with_room_to_drive_in():
    w, lane = _world()
    car = w.add_agent(AgentKind.CAR, lane, 2.0, speed=5.0)
    st = w._state
    y0 = w.map.lanes.polyline(lane)[0, 1]  # where the lane starts (s = 0)
    # slots far enough ahead to stop at 2 m/s^2 (+3 m): y >= -45.75; -43 is taken, -37
    # has the car parked at -43 in its run-in, -31 is free with one car length behind it
    s, lat = pullin.find_space(w.map, st, car)
    assert 5.0 ** 2 / (2 * pullin.PICK_DECEL) + 3.0 <= s - 2.0
    assert s == pytest.approx(-31.0 - y0, abs=0.01)
    edge = -lat - st["hw"][car] - LW / 2  # lane-side wheels beyond the road edge [m]
    assert -0.15 <= edge <= 0.35
    # a bin in that space: the next one (-25) has the car parked at -19 too close ahead
    w.map.obstacles = Obstacles(np.array([[LW + 1.0, -31.0]]), np.zeros(1), np.full(1, 0.6),
                                np.full(1, 0.6), np.zeros(1), np.full(1, 1.1),
                                np.zeros(1, np.uint8))
    assert pullin.find_space(w.map, st, car) is None


def test_car_pulls_in_stops_parked_in_the_strip_and_turns_static():
    w, lane = _world()
    car = w.add_agent(AgentKind.CAR, lane, 8.0, speed=5.0)
    follower = w.add_agent(AgentKind.CAR, lane, 1.0, speed=0.0)
    st = w._state
    n_rows = len(st["v"])
    assert pullin.start_pull_ins(w.map, st, 1e3, 0.1, np.random.default_rng(0)) >= 1
    target = st["park"][car].copy()
    y0 = w.map.lanes.polyline(lane)[0, 1]
    assert target[0] == pytest.approx(-31.0 - y0, abs=0.01)
    spec = GridSpec()
    r0, c0 = (int(k) for k in spec.to_cell(np.array(0.0), np.array(0.0)))
    labels, speeds = [], []
    for _ in range(300):
        w.step(HOLD)
        assert _overlaps(w) == 0
        a = w.agents
        speeds.append(a.speed[car])
        # the car is a body on the lane for the follower until it is out of the lane
        if a.xy[car, 0] - a.width[car] / 2 < LW - 0.05:
            assert a.xy[follower, 1] + a.length[follower] / 2 < \
                a.xy[car, 1] - a.length[car] / 2 + 0.3
        pose = np.array([*a.xy[car], a.yaw[car]])  # the label under the car's centre
        lab = label_grid(w.map, a, pose, spec)
        labels.append(CLASSES[lab[r0, c0]])
        if a.parked[car]:
            break
    a, st = w.agents, w._state
    assert a.parked[car] and not st["mobile"][car] and a.speed[car] == 0.0
    assert len(st["v"]) == n_rows  # no agent added
    # ends at its target: centre over the slot, heading along the kerb
    assert a.xy[car, 1] == pytest.approx(y0 + target[0], abs=0.06)
    assert a.yaw[car] == pytest.approx(np.pi / 2, abs=1e-6)
    # inside the strip: every corner between the road edge (0.1 m slack) and the strip's
    # outer edge, on kerbside ground, and not touching a parked car
    corners = a.corners()[car]
    assert corners[:, 0].min() >= LW - 0.1 and corners[:, 0].max() <= LW + STRIP + 0.05
    inner = box_corners(*a.xy[car], a.yaw[car], a.length[car] - 0.2, a.width[car] - 0.3)
    assert (lookup(w.map, inner) == MapClass.INTERMEDIATE).all()
    # braked comfortably, then stood: moving, then static
    decel = -np.diff(speeds) / 0.1
    assert decel.max() <= PARK_DECEL * 1.05  # (on the braking curve: far from the space)
    assert labels[0] == "moving" and labels[-1] == "static"
    assert labels.index("static") > 10 and "moving" not in labels[labels.index("static"):]
    for _ in range(60):  # the follower drives on past it
        w.step(HOLD)
    assert w.agents.xy[follower, 1] > a.xy[car, 1]
    assert w.agents.parked[car] and (w.agents.xy[car] == a.xy[car]).all()


def test_city_pull_ins_are_seeded_keep_traffic_steady_and_never_overlap():
    runs = []
    for run in range(2):
        w = World(BUSY, seed=7)
        st = w._state
        n_rows, mobile0 = len(st["v"]), int(st["mobile"].sum())
        parked_ever, traj = set(), []
        for step in range(400):
            was = st["park"][:, 0] >= 0
            w.step()
            traj.append(w.agents.xy.copy())
            parked_ever |= set(np.flatnonzero(was & st["parked"]).tolist())
            if run == 0 and step % 4 == 0:
                assert _overlaps(w) == 0
        assert len(st["v"]) == n_rows
        assert int(st["mobile"].sum()) == mobile0  # a far parked car left for each
        runs.append((parked_ever, traj))
    assert len(runs[0][0]) >= 2
    assert runs[0][0] == runs[1][0]
    assert all(np.array_equal(a, b) for a, b in zip(runs[0][1], runs[1][1]))


def test_zero_rate_never_starts_a_pull_in():
    w = World({**BUSY, "traffic": {**BUSY["traffic"], "pull_in_rate": 0.0}}, seed=7)
    for _ in range(200):
        w.step()
        assert (w._state["park"][:, 0] < 0).all()


@pytest.mark.skipif(not numpy_math_is_libm(), reason="numpy's SIMD math differs "
                    "from libm on this CPU (AVX-512): the bit-exact digest is for libm")
def test_zero_rate_reproduces_the_traffic_before_pull_ins():
    """With ``pull_in_rate = 0`` the traffic step (which now carries the pull-in state)
    gives the trajectories of the code before pull-ins bit for bit: the digest was taken
    with commit 90fcc83 (no pull-ins) running this scene (two-lane signalised cross, 12
    cars, cyclists, a delivery stop; 300 steps), and re-taken when uncontrolled nodes
    whose connectors conflict became yield junctions (this map's dead-end U-turns: the
    old digest 4333932498d1298d holds for the code before that rule). A numba / numpy
    upgrade that changes rounding would change it too."""
    import hashlib

    w = World({"traffic": {"cars": 0, "cyclists": 0, "pedestrians": 0, "pull_in_rate": 0.0}},
              seed=5, world_map=cross_map(Control.SIGNAL, 2))
    net = w.map.lanes
    for x, y in ((LW / 2, -TRIM), (1.5 * LW, -TRIM), (-LW / 2, TRIM), (TRIM, LW / 2)):
        lane = lane_ending_near(net, x, y)
        for s in (5.0, 17.0, 29.0):
            w.add_agent(AgentKind.CAR, lane, s, speed=6.0)
        if net.rightmost[lane]:
            w.add_agent(AgentKind.CYCLIST, lane, 40.0, speed=4.0)
    k = w.add_agent(AgentKind.CAR, lane_ending_near(net, 1.5 * LW, -TRIM), 44.0)
    w._state["halt"][k] = 8.0  # a delivery stop in the kerb lane
    h = hashlib.sha256()
    for _ in range(300):
        w.step()
        a = w.agents
        for arr in (a.xy, a.yaw, a.speed, w.ego_pose):
            h.update(np.ascontiguousarray(arr).tobytes())
    assert h.hexdigest()[:16] == "b8cd2310e49ae936"


def test_pull_in_rate_is_validated_by_name():
    with pytest.raises(ValueError, match="traffic.pull_in_rate"):
        World({"traffic": {"pull_in_rate": -0.01}}, seed=0)
