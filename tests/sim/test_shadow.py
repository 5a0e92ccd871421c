"""The shadow autopilot: what the autopilot would do, while something else drives."""

from __future__ import annotations

import numpy as np

import dstenv.sim.world as world_module
from dstenv.sim import World
from dstenv.sim.shadow import ShadowAutopilot

CITY = {"map": {"blocks_x": 2, "blocks_y": 2},
        "traffic": {"cars": 10, "cyclists": 1, "pedestrians": 4}}


def _state(w: World) -> dict[str, np.ndarray]:
    return {k: a.copy() for k, a in w._state.items()}


def test_the_shadow_changes_nothing_in_the_world():
    plain, shadowed = World(CITY, seed=3), World(CITY, seed=3)
    shadowed.shadow = ShadowAutopilot()
    shadowed.reset(3)
    commands = set()
    for k in range(150):
        action = (1.0 if k % 40 < 25 else -2.0, plain.route_steer())
        plain.step(action)
        shadowed.step(action)
        commands.add(shadowed.shadow.command)
    a, b = _state(plain), _state(shadowed)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert plain.rng.bit_generator.state == shadowed.rng.bit_generator.state
    assert len(commands) > 50  # it was asked every step, and its answers changed


def test_the_shadow_says_what_the_autopilot_does(monkeypatch):
    """With the autopilot driving, the shadow's command before each step is the
    acceleration and steering the step applies, and its junction state is the ego's."""
    applied = []
    step = world_module.bicycle_step

    def record(x, y, yaw, v, accel, steer, *rest):
        applied.append((accel, steer))
        return step(x, y, yaw, v, accel, steer, *rest)

    monkeypatch.setattr(world_module, "bicycle_step", record)
    granted, braked = 0, 0
    for seed in (0, 1):
        w = World(CITY, seed=seed)
        w.shadow = ShadowAutopilot()
        w.reset(seed)
        for _ in range(300):
            expected = w.shadow.command
            queue = (w.shadow.grant, w.shadow.req_t, w.shadow.stop_clock)
            w.step(None)  # it queues the ego from the state the shadow was asked about
            assert applied[-1] == expected
            st = w._state
            assert queue == (st["grant"][-1], st["req_t"][-1], st["stop_clock"][-1])
            granted += w.shadow.grant >= 0
            braked += expected[0] < -0.5
    assert granted > 10 and braked > 5  # it met junctions and slowed for something


def test_a_new_episode_forgets_the_grant():
    w = World(CITY, seed=0)
    w.shadow = ShadowAutopilot()
    w.shadow.grant, w.shadow.stop_clock = 7, 3.0  # as if left over from an episode
    w.reset(1)
    assert w.shadow.stop_clock in (0.0, 0.1) and w.shadow.command is not None


def test_adding_an_agent_does_not_step_the_shadow():
    w = World(CITY, seed=0)
    w.shadow = ShadowAutopilot()
    w.reset(0)
    w.shadow.stop_clock = 1.0  # as if standing at a stop line
    lane = int(w.route[0])
    w.add_agent(world_module.AgentKind.CAR, lane, 0.0)
    assert w.shadow.stop_clock == 1.0  # the shadow is asked once per world step only
