"""What the autopilot would do now, while something else drives the ego.

A privileged teacher for learners that drive the ego themselves (imitation of the
autopilot on the learner's own states, DAgger-style): :class:`ShadowAutopilot`,
attached to a :class:`~dstenv.sim.World` as ``world.shadow``, is updated by the world
after every reset and step and holds the ``(accel, steer)`` the autopilot would
apply from the current state (:attr:`ShadowAutopilot.command`).

It runs the traffic kernel (:func:`dstenv.sim.traffic.traffic_step`) with the ego
planning on a copy of the agent table and keeps the ego's own right-of-way state
(its junction grant, request time and stop-sign clock) between steps, so it queues
at junctions and makes full stops at stop signs as the autopilot does. Nothing of the
world changes: the traffic does not know of the shadow's grants (the ego that really
drives is not in the junctions' queue), and the world's random stream is untouched.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dstenv.sim import agenttable
from dstenv.sim.traffic import n_randoms, traffic_step

__all__ = ["ShadowAutopilot", "autopilot_limit"]


def autopilot_limit(acc: float, gap: float, v: float, dt: float) -> float:
    """The autopilot's acceleration [m/s^2]: the IDM's ``acc``, never further than the
    free ``gap`` [m] ahead at the end of the step (like the traffic agents), at speed
    ``v`` [m/s] and step ``dt`` [s]."""
    room = max(gap - 0.05, 0.0)
    if room >= v * dt / 2:  # reaches ``room`` at the end of the step at the latest
        limit = 2.0 * (room - v * dt) / dt ** 2
    else:  # has to stop within the step
        limit = -v * v / (2.0 * room) if room > 0 else -1e9
    return float(min(acc, limit))


class ShadowAutopilot:
    """The autopilot's command for the current state of a world it does not drive.

    Attributes:
        command: ``(accel [m/s^2], steer [rad])`` the autopilot would apply in the next
            step (``None`` before the first update).
        grant, req_t, stop_clock: the shadow ego's right of way: the connector it has
            been granted (-1: none), when it asked [s] (``inf``: not asking), how long
            it has stood at a stop line [s].
    """

    def __init__(self) -> None:
        self.command: tuple[float, float] | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the right-of-way state (a new episode)."""
        self.grant, self.req_t, self.stop_clock = -1, float(np.inf), 0.0

    def update(self, world: Any, reset: bool = False) -> tuple[float, float]:
        """Compute :attr:`command` from ``world``'s current state (once per world step:
        the stop-sign clock advances by ``dt`` per call), first forgetting the
        right-of-way state with ``reset`` (a new episode, the ego moved by hand)."""
        st = world._state
        route = st["route"][-1]
        if reset or (self.grant >= 0 and self.grant not in route):  # stale: re-planned
            self.reset()
        table = {k: a.copy() for k, a in st.items()}  # the kernel writes in place
        table["grant"][-1], table["req_t"][-1] = self.grant, self.req_t
        table["stop_clock"][-1] = self.stop_clock
        dt = world.config["dt"]
        u = np.zeros((len(st["v"]), n_randoms(route.shape[0])))
        acc, gap, _ = traffic_step(
            world._net, world._nbr, world.map.lanes.heading_trig,
            agenttable.state_tuple(table), table["idm"],
            agenttable.rules_tuple(world.config["traffic"], world.map.lanes.lane_width),
            world.time, dt, u, True)
        self.grant = int(table["grant"][-1])
        self.req_t = float(table["req_t"][-1])
        self.stop_clock = float(table["stop_clock"][-1])
        self.command = (autopilot_limit(acc, gap, float(st["v"][-1]), dt), world.route_steer())
        return self.command
