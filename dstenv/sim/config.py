"""Default configuration of the world simulator (map, traffic, ego, driving task).

The dict is plain data, HighwayEnv style: units in comments, overridden with
:func:`dstenv.config.merge_config` (unknown keys are rejected by name). It is the
``world`` section of the pipeline's configuration.
"""

from __future__ import annotations

from typing import Any

__all__ = ["default_config", "MAP_KINDS"]

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
            "building_height_min": 6.0,  # [m] roof height of generated buildings, at least
            "building_height_max": 30.0,  # [m] at most (whole ~3 m storeys + roof)
            "kerb_height": 0.12,  # [m] sidewalks / verges (INTERMEDIATE cells) above the road
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
