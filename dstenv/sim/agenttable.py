"""The agent state table: the world state is one dict of structure-of-arrays over B
rows, the ego last:
``xy (B,2)``, ``yaw``, ``v``, ``hl``/``hw`` (half length / width), ``akind``
(:class:`AgentKind`), ``mobile``, ``parked``, ``route (B,K)`` lanes ahead,
``s`` arc length on ``route[:,0]``, ``lat`` lateral offset (left +) and the
``lat_goal`` it returns to, junction
``grant`` (reserved connector), request time ``req_t``, ``stop_clock``, ``halt``
timer, ``stuck``, ``still`` (standstill time), ``lc`` (lane change / pass, see
:mod:`dstenv.sim.lanechange`), ``hazard`` (double parked, hazard lights on), ``park
(B,2)`` (a car pulling into a space: target arc length on ``route[:,0]`` and lateral
offset [m]; -1 / 0 when none, see :mod:`dstenv.sim.pullin`), ``idm
(B,5)`` (desired speed, accel, comfortable decel, headway, jam gap) and ``height``
[m] (body height).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dstenv.sim.lanes import LaneNetwork
from dstenv.sim.types import AGENT_HEIGHT, AgentKind

__all__ = ["FIELDS", "add_row", "empty_table", "insert_rows", "net_tuple", "no_park",
           "rules_tuple", "state_tuple"]

_TRAFFIC_FIELDS = ("xy", "yaw", "v", "hl", "hw", "akind", "mobile", "parked", "route", "s",
                   "lat", "grant", "req_t", "stop_clock", "halt", "stuck", "still", "lat_goal",
                   "lc", "hazard", "park")
#: every field of the table, in the order rows are inserted
FIELDS = (*_TRAFFIC_FIELDS, "idm", "height")


def net_tuple(net: LaneNetwork) -> tuple:
    """Lane-network arrays in the order :func:`dstenv.sim.traffic.traffic_step` expects."""
    return (net.pts, net.hdg, net.start, net.npts, net.ds, net.length, net.kind, net.node,
            net.turn, net.group, net.vmax, net.succ_ptr, net.succ, net.conf_ptr, net.conf,
            net.node_control, net.node_phase)


def state_tuple(st: dict[str, np.ndarray]) -> tuple:
    """State arrays in the order :func:`dstenv.sim.traffic.traffic_step` expects."""
    return tuple(st[k] for k in _TRAFFIC_FIELDS)


def rules_tuple(tr: dict[str, Any], lane_width: float) -> tuple:
    """Traffic-rule parameters for :func:`dstenv.sim.traffic.traffic_step` (``lane_width``
    [m]: the network's, sets the lane-change speed)."""
    return tuple(float(tr[k]) for k in ("signal_green", "stop_duration", "halt_rate",
                                        "halt_duration", "pause_rate", "pause_duration",
                                        "crossing_prob", "lateral_drift", "drift_time",
                                        "lateral_speed", "delivery_halt_factor",
                                        "lane_change_rate", "lane_change_time")) + (
        float(lane_width),)


def empty_table(k: int) -> dict[str, np.ndarray]:
    """A table of no rows whose ``route`` holds ``k`` lanes."""
    return {"xy": np.zeros((0, 2)), "yaw": np.zeros(0), "v": np.zeros(0), "hl": np.zeros(0),
            "hw": np.zeros(0), "akind": np.zeros(0, np.uint8), "mobile": np.zeros(0, bool),
            "parked": np.zeros(0, bool), "route": np.zeros((0, k), np.int64), "s": np.zeros(0),
            "lat": np.zeros(0), "grant": np.zeros(0, np.int64), "req_t": np.zeros(0),
            "stop_clock": np.zeros(0), "halt": np.zeros(0), "stuck": np.zeros(0, bool),
            "still": np.zeros(0), "lat_goal": np.zeros(0), "lc": np.zeros(0),
            "hazard": np.zeros(0, bool), "park": np.zeros((0, 2)), "idm": np.zeros((0, 5)),
            "height": np.zeros(0)}


def add_row(st: dict[str, np.ndarray], kind: AgentKind, xy, yaw: float, length: float,
            width: float, *, speed: float = 0.0, parked: bool = False, route=None, s: float = 0.0,
            lat: float = 0.0, idm=(0.0, 1.0, 1.0, 1.0, 1.0), at: int | None = None,
            height: float | None = None) -> int:
    """Insert one agent row (before row ``at``; default: append). Returns its index.

    ``height`` [m] defaults to :data:`AGENT_HEIGHT` of ``kind``."""
    k = st["route"].shape[1]
    row = {"xy": np.asarray(xy, float).reshape(1, 2), "yaw": [yaw], "v": [speed],
           "hl": [length / 2], "hw": [width / 2], "akind": [int(kind)],
           "mobile": [route is not None and not parked], "parked": [parked],
           "route": (np.full((1, k), -1) if route is None else np.asarray(route).reshape(1, k)),
           "s": [s], "lat": [lat], "grant": [-1], "req_t": [np.inf], "stop_clock": [0.0],
           "halt": [0.0], "stuck": [False], "still": [0.0], "lat_goal": [lat], "lc": [0.0],
           "hazard": [False], "park": np.array([[-1.0, 0.0]]),
           "idm": np.asarray(idm, float).reshape(1, 5),
           "height": [AGENT_HEIGHT[int(kind)] if height is None else height]}
    at = len(st["v"]) if at is None else at
    for f in FIELDS:  # (np.concatenate: the same as np.insert, without its overhead)
        a = st[f]
        st[f] = np.concatenate([a[:at], np.asarray(row[f], dtype=a.dtype).reshape(1, *a.shape[1:]),
                                a[at:]])
    return at


def no_park(n: int) -> np.ndarray:
    """``(n, 2)`` rows of ``park`` for agents that are not pulling into a space."""
    return np.tile([-1.0, 0.0], (n, 1))


def insert_rows(st: dict[str, np.ndarray], rows: dict[str, np.ndarray], at: int) -> None:
    """Insert the rows (one array per field of :data:`FIELDS`) before row ``at``."""
    for f in FIELDS:
        a = st[f]
        st[f] = np.concatenate([a[:at], rows[f].astype(a.dtype, copy=False), a[at:]])
