"""Default configuration of the world simulator (map, traffic, ego, driving task).

The dict is plain data, HighwayEnv style: units in comments, overridden with
:func:`dstenv.config.merge_config` (unknown keys are rejected by name). It is the
``world`` section of the pipeline's configuration.
"""

from __future__ import annotations

from typing import Any

from dstenv.config import PROB, Section, at_least, between, one_of
from dstenv.sim.clutter import default_clutter_config

__all__ = ["default_config", "MAP_KINDS", "SECTION"]

#: Accepted values of ``map.kind``.
MAP_KINDS = ("procedural", "osm")


def default_config() -> dict[str, Any]:
    """The complete default world configuration (a new dict on each call)."""
    cfg: dict[str, Any] = {
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
            "parking_prob": 0.45,  # [-] chance that a block side has a parking strip
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
            # -- variety (0 / "lattice" everywhere: the ideal world of the clean scenario)
            "lane_width_jitter": 0.45,  # [m] lane width of each street: lane_width +- this (0..0.7)
            "curb_strip_jitter": 0.5,  # [m] kerb strip width of an episode: +- this (0..1)
            "sidewalk_jitter": 0.6,  # [m] sidewalk width of an episode: +- this (0..1)
            "parking_layout": "irregular",  # "irregular" (gaps, jitter, size mix) | "lattice"
            "parking_gap_min": 0.5,  # [m] gap between two parked vehicles, at least
            "parking_gap_max": 3.0,  # [m] at most (irregular layout)
            "parking_lateral_jitter": 0.3,  # [m] offset in the strip: per side +- this, per car /2
            "parking_heading_jitter": 2.0,  # [deg] std of a parked vehicle's heading error
            "parking_mix": [0.25, 0.55, 0.15, 0.05],  # weights of small car, car, van, truck
            # [-] share of (small / normal) cars parked half on the sidewalk
            "half_on_sidewalk_prob": 0.08,
            # off-street parking lots in place of a block side's buildings (dstenv.sim.lots)
            "lot_prob": 0.0,  # [-] chance that a block side is a lot (0: none, as before)
            "lot_depth": 22.0,  # [m] depth of a lot behind the sidewalk, at most
            "lot_fill": 0.7,  # [-] chance that a stall holds a car
            # -- geometry (0 everywhere: the straight Manhattan grid of the clean scenario)
            "shear_deg": 15.0,  # [deg] streets meet at 90 +- up to this (drawn per map, 0..30)
            "bend_amplitude": 7.0,  # [m] sideways bend of straight streets (0..30; 0: straight)
            "bend_wavelength": 300.0,  # [m] length of one bend wave (slope 2 pi a / l <= 0.25)
            "roundabout_prob": 0.15,  # [-] chance that a 4-way junction becomes a roundabout
            "median_prob": 0.4,  # [-] chance that a street with >= 2 lanes per way has a median
            "median_width": 2.0,  # [m] raised median strip between the two directions (0.5..8)
        },
        "traffic": {
            "cars": 70,  # moving cars (KITTI-like class mix: moving >= static)
            "cyclists": 14,
            "pedestrians": 45,
            "parked_density": 0.08,  # [-] share of parking-strip slots holding a parked car
            # weights of small car, car, van, truck among moving cars ([]: one car size)
            "vehicle_mix": [0.15, 0.65, 0.15, 0.05],
            "speed_limit": 13.9,  # [m/s] desired speed of cars (50 km/h), +-20 % per car
            "cyclist_speed": 5.0,  # [m/s]
            "pedestrian_speed": 1.3,  # [m/s]
            "stop_sign_prob": 0.35,  # [-] share of junctions that are all-way stops
            "signal_prob": 0.35,  # [-] share of junctions with traffic lights (rest: yield)
            "signal_green": 12.0,  # [s] green per phase (none enter its last 3 s; 3 s all-red)
            "stop_duration": 1.5,  # [s] standstill required at a stop sign
            "halt_rate": 0.01,  # [1/s] chance per second that a car halts in its lane
            "halt_duration": 6.0,  # [s] mean duration of such a halt (exponential, at most 4x)
            "pause_rate": 0.05,  # [1/s] chance per second that a pedestrian stands still
            "pause_duration": 5.0,  # [s] mean pause of a pedestrian (exponential, at most 4x)
            "crossing_prob": 0.4,  # [-] chance a pedestrian takes a crosswalk it reaches
            "lateral_drift": 0.15,  # [m] std of a vehicle's drift around its lane centre (0..0.5)
            "drift_time": 3.0,  # [s] correlation time of that drift
            "lateral_speed": 0.6,  # [m/s] sideways speed of a car pulling out of a space
            "pull_out_rate": 0.002,  # [1/s] chance per second that a parked car pulls out
            # [1/s] chance per second that a moving car on a kerb-side lane pulls into a
            # free space ahead (a parked car far from the ego pulls out for each)
            "pull_in_rate": 0.01,
            "delivery_halt_factor": 4.0,  # [-] vans / trucks halt this much longer than cars
            # -- double parking and lane changes (0 in the clean scenario)
            "double_park_prob": 0.03,  # [-] share of parked vehicles standing in the kerb
            #                            lane beside their space instead (hazards on)
            "double_park_duration": 60.0,  # [s] mean dwell before it drives off (exp., <= 4x)
            "lane_change_rate": 0.01,  # [1/s] lane changes without a reason, per car on a
            #                            multi-lane street (overtaking a slow vehicle is apart)
            "lane_change_time": 4.0,  # [s] a lane change (one lane width sideways) takes ~this
        },
        "clutter": default_clutter_config(),
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
    # map reuse across episodes (kept apart from the generator's keys above)
    cfg["map"].update({
        "pool": 0,  # [maps] episodes draw from this many maps generated once (Procgen's
        #             num_levels); 0 = a new map from every episode seed
    })
    return cfg


_M, _MS, _MS2 = "m", "m/s", "m/s^2"


def _mix(key: str, allow_empty: bool) -> tuple[str, Any, str]:
    """A size-mix check: 4 weights >= 0, not all 0 (or [] where one size is allowed)."""
    def ok(c: Any) -> bool:
        section, name = key.split(".")
        w = c[section][name]
        return (allow_empty and len(w) == 0) or (len(w) == 4 and min(w) >= 0 and sum(w) > 0)
    empty = "[] (one car size) or " if allow_empty else ""
    return (key, ok, f"must be {empty}4 weights >= 0 (small car, car, van, truck), not all 0")


def _jitter_ok(c: Any, jitter: str, width: str) -> bool:
    m = c["map"]
    return m[jitter] == 0.0 or m[jitter] <= min(1.0, m[width] - 1.0)


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
        "lane_width": between(2.5, 4.5, _M),
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
        "pool": between(0, 1000),  # each map kept in memory: ~13 MB at the defaults
        "gap_min": between(0.0, 100.0, _M),
        "gap_max": between(0.0, 100.0, _M),
        "osm_lane_width": between(2.0, 6.0, _M),
        "building_height_min": between(2.0, 100.0, _M),
        "building_height_max": between(2.0, 200.0, _M),
        "kerb_height": between(0.0, 0.5, _M),
        "lane_width_jitter": between(0.0, 0.7, _M),
        "curb_strip_jitter": between(0.0, 1.0, _M),
        "sidewalk_jitter": between(0.0, 1.0, _M),
        "parking_layout": one_of("irregular", "lattice"),
        "parking_gap_min": between(0.0, 20.0, _M),
        "parking_gap_max": between(0.0, 20.0, _M),
        "parking_lateral_jitter": between(0.0, 1.0, _M),
        "parking_heading_jitter": between(0.0, 15.0, "deg"),
        "parking_mix": between(0.0, 1e3),
        "half_on_sidewalk_prob": PROB,
        "lot_prob": PROB,
        "lot_depth": between(5.0, 100.0, _M),
        "lot_fill": PROB,
        "shear_deg": between(0.0, 30.0, "deg"),
        "bend_amplitude": between(0.0, 30.0, _M),
        "bend_wavelength": between(50.0, 5000.0, _M),
        "roundabout_prob": PROB,
        "median_prob": PROB,
        "median_width": between(0.5, 8.0, _M),
    },
    "traffic": {
        "cars": between(0, 500),
        "cyclists": between(0, 500),
        "pedestrians": between(0, 1000),
        "parked_density": PROB,
        "vehicle_mix": between(0.0, 1e3),
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
        "lateral_drift": between(0.0, 0.5, _M),
        "drift_time": between(0.2, 60.0, "s"),
        "lateral_speed": between(0.1, 3.0, _MS),
        "pull_out_rate": between(0.0, 0.1, "1/s"),
        "pull_in_rate": between(0.0, 0.1, "1/s"),
        "delivery_halt_factor": between(1.0, 20.0),
        "double_park_prob": PROB,
        "double_park_duration": between(0.0, 3600.0, "s"),
        "lane_change_rate": between(0.0, 1.0, "1/s"),
        "lane_change_time": between(1.0, 15.0, "s"),
    },
    "clutter": {
        "density": between(0.0, 5.0),
        "pole_spacing": between(2.0, 500.0, _M),
        "tree_spacing": between(2.0, 500.0, _M),
        "sign_rate": between(0.0, 50.0, "per 100 m"),
        "bin_rate": between(0.0, 50.0, "per 100 m"),
        "bicycle_rate": between(0.0, 50.0, "per 100 m"),
        "tree_side_prob": PROB,
        "bollard_prob": PROB,
        "shelter_prob": PROB,
        "front_prob": PROB,
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


def _le(a: str, b: str) -> tuple[str, Any, str]:
    """``a <= b`` for two keys of one section (``"map.x"``)."""
    (sa, ka), (sb, kb) = a.split("."), b.split(".")
    return (b, lambda c: c[sa][ka] <= c[sb][kb], f"must be >= {a}")


def _raster_cells(m: dict[str, Any]) -> float:
    """The largest procedural map's raster, in cells."""
    side = [(m[k] * m["block_max"] + 2 * m["margin"]) / m["resolution"]
            for k in ("blocks_x", "blocks_y")]
    return side[0] * side[1]


def _street_edge(m: dict[str, Any]) -> float:
    """[m] from an outer street's centre line to the back of its sidewalk, at most."""
    return (m["lanes_max"] * (m["lane_width"] + m["lane_width_jitter"]) + m["median_width"] / 2
            + m["curb_strip_width"] + m["sidewalk_width"])


#: The ``world`` section: defaults, rules and the checks that relate two keys.
SECTION = Section(default_config, RULES, (
    _le("map.lanes_min", "map.lanes_max"),
    _le("map.block_min", "map.block_max"),
    _le("map.setback_min", "map.setback_max"),
    _le("map.building_width_min", "map.building_width_max"),
    _le("map.building_depth_min", "map.building_depth_max"),
    _le("map.building_height_min", "map.building_height_max"),
    _le("map.gap_min", "map.gap_max"),
    _le("map.parking_gap_min", "map.parking_gap_max"),
    ("map.curb_strip_jitter", lambda c: _jitter_ok(c, "curb_strip_jitter", "curb_strip_width"),
     "must be in [0, min(1, curb_strip_width - 1)] m"),
    ("map.sidewalk_jitter", lambda c: _jitter_ok(c, "sidewalk_jitter", "sidewalk_width"),
     "must be in [0, min(1, sidewalk_width - 1)] m"),
    ("map.blocks_x", lambda c: _raster_cells(c["map"]) <= 1e9,
     "with blocks_y, block_max, margin and resolution: a raster of over 10^9 cells (~1 GB "
     "each, several per map); fewer or smaller blocks, or a coarser resolution"),
    ("map.sidewalk_width", lambda c: c["map"]["curb_strip_width"]
     + c["map"]["sidewalk_width"] >= 2.0,
     "with curb_strip_width: together >= 2 m (less parked cars overlap the buildings)"),
    ("map.margin", lambda c: c["map"]["margin"] >= _street_edge(c["map"]),
     "must reach past the outer streets' sidewalks: >= lanes_max * (lane_width + "
     "lane_width_jitter) + median_width / 2 + curb_strip_width + sidewalk_width (less put "
     "agents and the ego off the map)"),
    _mix("map.parking_mix", False),
    ("map.bend_amplitude", lambda c: 2 * 3.14159 * c["map"]["bend_amplitude"]
     <= 0.25 * c["map"]["bend_wavelength"],
     "must be <= 0.25 * map.bend_wavelength / (2 pi) (gentle bends: slope <= 0.25)"),
    _mix("traffic.vehicle_mix", True),
    ("ego.wheelbase", lambda c: c["ego"]["wheelbase"] <= c["ego"]["length"],
     "must be <= ego.length"),
))
