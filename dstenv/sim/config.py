"""Default configuration of the world simulator (map, traffic, ego, driving task).

The dict is plain data, HighwayEnv style: units in comments, overridden with
:func:`dstenv.config.merge_config` (unknown keys are rejected by name). It is the
``world`` section of the pipeline's configuration.
"""

from __future__ import annotations

from typing import Any

from dstenv.config import PROB, Section, at_least, between, one_of

__all__ = ["default_config", "MAP_KINDS", "SECTION"]

#: Accepted values of ``map.kind``.
MAP_KINDS = ("procedural", "osm")


def default_config() -> dict[str, Any]:
    """The complete default world configuration (a new dict on each call)."""
    return {
        "dt": 0.1,  # [s] simulation step (the Velodyne's 10 Hz)
        "map": {
            "kind": "procedural",  # "procedural" city generator | "osm" file
            "osm_file": "",  # path of a .osm / .osm.bz2 file (kind = "osm"); a relative
            #                  path is looked up in World(base_dir=...) (the scenario
            #                  file's folder for `dstenv render`), the current folder,
            #                  then the shipped scenarios
            "resolution": 0.2,  # [m] map raster cell size
            "margin": 35.0,  # [m] frontage beyond the outer streets / space around an OSM map
            "blocks_x": 5,  # number of blocks along x (procedural)
            "blocks_y": 5,  # number of blocks along y (procedural)
            "block_min": 50.0,  # [m] smallest street spacing (centre line to centre line)
            "block_max": 110.0,  # [m] largest street spacing
            "t_junction_prob": 0.3,  # [-] share of interior street segments removed (T junctions)
            "lanes_min": 1,  # lanes per direction, at least (1..3)
            "lanes_max": 2,  # lanes per direction, at most (1..3)
            "lane_width": 3.25,  # [m]
            "curb_strip_width": 2.2,  # [m] parking strip / verge between road and sidewalk
            "sidewalk_width": 2.5,  # [m]
            "parking_prob": 0.6,  # [-] chance that a block side has a parking strip
            "building_coverage": 0.85,  # [-] share of building slots that hold a building
            "setback_min": 0.0,  # [m] building setback behind the sidewalk, at least
            "setback_max": 4.0,  # [m] at most
            "building_width_min": 7.0,  # [m] frontage of one building
            "building_width_max": 28.0,  # [m]
            "building_depth_min": 9.0,  # [m]
            "building_depth_max": 22.0,  # [m]
            "gap_prob": 0.35,  # [-] chance of a gap (alley, driveway) after a building
            "gap_min": 2.0,  # [m]
            "gap_max": 7.0,  # [m]
            "osm_lane_width": 3.0,  # [m] lane width assumed for OSM ways without a width tag
        },
        "traffic": {
            "cars": 24,  # moving cars
            "cyclists": 4,
            "pedestrians": 14,
            "parked_density": 0.5,  # [-] share of parking-strip slots holding a parked car
            "speed_limit": 13.9,  # [m/s] desired speed of cars (50 km/h), +-20 % per car
            "cyclist_speed": 5.0,  # [m/s]
            "pedestrian_speed": 1.3,  # [m/s]
            "stop_sign_prob": 0.35,  # [-] share of junctions that are all-way stops
            "signal_prob": 0.35,  # [-] share of junctions with traffic lights (rest: yield)
            "signal_green": 12.0,  # [s] green per phase (none enter its last 3 s; 3 s all-red)
            "stop_duration": 1.5,  # [s] standstill required at a stop sign
            "halt_rate": 0.01,  # [1/s] chance per second that a car halts in its lane
            "halt_duration": 6.0,  # [s] mean duration of such a halt (exponential, at most 4x)
            "pause_rate": 0.03,  # [1/s] chance per second that a pedestrian stands still
            "pause_duration": 5.0,  # [s] mean pause of a pedestrian (exponential, at most 4x)
            "crossing_prob": 0.4,  # [-] chance a pedestrian takes a crosswalk it reaches
        },
        "ego": {
            "length": 4.5,  # [m]
            "width": 1.9,  # [m]
            "wheelbase": 2.7,  # [m]
            "max_speed": 15.0,  # [m/s]
            "max_accel": 3.0,  # [m/s^2] |acceleration| limit of the controlled ego
            "max_steer": 0.6,  # [rad] steering angle limit
            "autopilot_speed": 10.0,  # [m/s] desired speed of the autopilot
            "initial_speed": 0.0,  # [m/s]
        },
        "task": {
            "cross_traffic": 0,  # cars placed on side streets of the ego's next junctions
            "parked_near_route": 0,  # parked cars placed along the ego's route
            "crossing_pedestrians": 0,  # pedestrians about to cross near the ego's route
        },
    }


_M, _MS, _MS2 = "m", "m/s", "m/s^2"

#: Rules of every ``world`` key: finite ranges with sane upper bounds (a typo such as
#: ``cars = 1e6`` is an error, not an hour of spawning).
RULES: dict[str, Any] = {
    "dt": between(0.0, 1.0, "s", lo_open=True),
    "map": {
        "kind": one_of(*MAP_KINDS),
        "resolution": between(0.01, 2.0, _M, lo_open=True),
        "margin": between(0.0, 500.0, _M),
        "blocks_x": between(1, 40),
        "blocks_y": between(1, 40),
        "block_min": between(30.0, 1000.0, _M),
        "block_max": between(30.0, 1000.0, _M),
        "t_junction_prob": PROB,
        "lanes_min": between(1, 3),
        "lanes_max": between(1, 3),
        "lane_width": between(2.0, 6.0, _M),
        "curb_strip_width": between(0.0, 10.0, _M),
        "sidewalk_width": between(0.0, 15.0, _M),
        "parking_prob": PROB,
        "building_coverage": PROB,
        "setback_min": between(0.0, 50.0, _M),
        "setback_max": between(0.0, 50.0, _M),
        "building_width_min": between(2.0, 200.0, _M),
        "building_width_max": between(2.0, 200.0, _M),
        "building_depth_min": between(2.0, 200.0, _M),
        "building_depth_max": between(2.0, 200.0, _M),
        "gap_prob": PROB,
        "gap_min": between(0.0, 100.0, _M),
        "gap_max": between(0.0, 100.0, _M),
        "osm_lane_width": between(2.0, 6.0, _M),
    },
    "traffic": {
        "cars": between(0, 500),
        "cyclists": between(0, 500),
        "pedestrians": between(0, 1000),
        "parked_density": PROB,
        "speed_limit": between(0.0, 60.0, _MS),
        "cyclist_speed": between(0.0, 20.0, _MS),
        "pedestrian_speed": between(0.0, 5.0, _MS),
        "stop_sign_prob": PROB,
        "signal_prob": PROB,
        "signal_green": between(4.0, 600.0, "s"),
        "stop_duration": between(0.0, 60.0, "s"),
        "halt_rate": between(0.0, 10.0, "1/s"),
        "halt_duration": between(0.0, 600.0, "s"),
        "pause_rate": between(0.0, 10.0, "1/s"),
        "pause_duration": between(0.0, 600.0, "s"),
        "crossing_prob": PROB,
    },
    "ego": {
        "length": between(1.0, 20.0, _M),
        "width": between(0.5, 5.0, _M),
        "wheelbase": between(0.5, 20.0, _M),
        "max_speed": between(0.0, 60.0, _MS, lo_open=True),
        "max_accel": between(0.0, 20.0, _MS2, lo_open=True),
        "max_steer": between(0.0, 1.2, "rad", lo_open=True),
        "autopilot_speed": between(0.0, 60.0, _MS),
        "initial_speed": between(0.0, 60.0, _MS),
    },
    "task": {
        "cross_traffic": at_least(0, 50),
        "parked_near_route": at_least(0, 200),
        "crossing_pedestrians": at_least(0, 50),
    },
}

#: The ``world`` section: defaults, rules and the checks that relate two keys.
SECTION = Section(default_config, RULES, (
    ("map.lanes_max", lambda c: c["map"]["lanes_min"] <= c["map"]["lanes_max"],
     "must be >= map.lanes_min"),
    ("map.block_max", lambda c: c["map"]["block_min"] <= c["map"]["block_max"],
     "must be >= map.block_min"),
    ("map.setback_max", lambda c: c["map"]["setback_min"] <= c["map"]["setback_max"],
     "must be >= map.setback_min"),
    ("map.building_width_max",
     lambda c: c["map"]["building_width_min"] <= c["map"]["building_width_max"],
     "must be >= map.building_width_min"),
    ("map.building_depth_max",
     lambda c: c["map"]["building_depth_min"] <= c["map"]["building_depth_max"],
     "must be >= map.building_depth_min"),
    ("map.gap_max", lambda c: c["map"]["gap_min"] <= c["map"]["gap_max"],
     "must be >= map.gap_min"),
    ("ego.wheelbase", lambda c: c["ego"]["wheelbase"] <= c["ego"]["length"],
     "must be <= ego.length"),
))
