"""Default configuration of the sensing subsystem (sections ``lidar``, ``gis``, ``labels``).

Each section is a plain dict with units in comments (HighwayEnv style) and a rule
table (:class:`dstenv.config.Section`); :func:`dstenv.config.build_config` validates
them: an unknown key or a value out of range raises
:class:`dstenv.config.ConfigError` naming it and the allowed values. The pipeline puts
these sections next to ``world``, ``grid`` and ``dst`` in its own config.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from dstenv.config import PROB, Section, between, one_of, section
from dstenv.sensing.carshape import VEHICLE_SHAPES

__all__ = [
    "LIDAR_MODELS",
    "default_hdl64_config",
    "default_config",
    "default_lidar_config",
    "default_gis_config",
    "default_labels_config",
    "lidar_config",
    "gis_config",
    "gis_is_exact",
    "labels_config",
    "LIDAR",
    "GIS",
    "LABELS",
]


#: ``lidar.model`` values: the fast 2-D scanner or the 3-D Velodyne HDL-64E-like one.
LIDAR_MODELS: tuple[str, ...] = ("2d", "hdl64")


def default_hdl64_config() -> dict[str, Any]:
    """The ``lidar.hdl64`` section: a spinning 64-channel LIDAR like KITTI's HDL-64E."""
    from dstenv.sensing.cloud import default_ray_config
    from dstenv.sensing.ground import default_ground_config

    return {
        "channels": 64,  # elevation channels [-], spread evenly from top to bottom
        "elevation_top": 2.0,  # [deg] highest channel (HDL-64E: +2.0)
        "elevation_bottom": -24.9,  # [deg] lowest channel (HDL-64E: -24.9)
        "azimuth_step": 0.17578125,  # [deg] between firings of a channel (2048 per turn)
        "mount_height": 1.73,  # [m] sensor above the road (KITTI's Velodyne)
        "max_range": 120.0,  # [m] slant range of a return
        "min_range": 2.0,  # [m] near blind zone: closer returns are discarded
        "range_noise": 0.02,  # [m] std of Gaussian range noise
        "dropout": 0.05,  # probability that a return is lost [-]
        # returns on agents fade with range and incidence (dstenv.sensing.fading):
        # P(detected) = Phi(ln(rho cos(incidence) (fade_range / r)^2) / fade_sigma)
        "fade_range": 0.0,  # [m] unit reflectivity, head-on: detected half the time; 0: off
        "fade_sigma": 1.0,  # [-] std of the natural log of a return's strength
        # "box": agents are prisms from the road to their height; "car": cars are a
        # body on wheels (clearance, cut corners, cabin; dstenv.sensing.carshape)
        "vehicle_shape": "box",
        "intensity_noise": 0.03,  # std of additive reflectance noise [-]
        "spin_rate": 10.0,  # [Hz] one turn per LIDAR period; 0: no within-sweep skew
        "channel_seed": 64,  # seed of the fixed per-channel gain (a calibration table)
        # the point cloud -> grid road shared with KITTI (dstenv.sensing.cloud)
        "ground": default_ground_config(),
        "rays": default_ray_config(),
    }


def default_lidar_config() -> dict[str, Any]:
    """The ``lidar`` section: a 2-D scanning LIDAR (a Velodyne sliced to the ground plane),
    or with ``model = "hdl64"`` the 3-D LIDAR of the ``hdl64`` sub-section."""
    return {
        "model": "2d",  # "2d" (fast, beams in the scan plane) or "hdl64" (3-D point cloud)
        "hdl64": default_hdl64_config(),
        "beams": 1800,  # number of beams per sweep [-] (0.2 deg spacing over 360 deg)
        "fov": 360.0,  # horizontal field of view [deg], centred on ego-forward
        "max_range": 80.0,  # [m]; beyond it a beam has no return
        "range_noise": 0.0,  # std of additive Gaussian range noise on returns [m]
        "dropout": 0.0,  # probability that a beam yields no measurement at all [-]
        "mount_x": 0.0,  # sensor position ahead of the ego centre [m]
        "mount_y": 0.0,  # sensor position left of the ego centre [m]
        # height of the horizontal scan plane above the road [m]: street clutter
        # (WorldMap.obstacles) occludes only where z_min <= plane_height <= z_max, so
        # tree crowns and sign panels above it do not; agents and buildings always do
        "plane_height": 0.5,
        # building occlusion geometry: "polygons" (exact, WorldMap.buildings),
        # "raster" (exact DDA over BUILDING cells of WorldMap.raster) or "auto"
        # (polygons when the map has any, else the raster)
        "buildings": "auto",
    }


def default_gis_config() -> dict[str, Any]:
    """The ``gis`` section: the map behind the GIS grid, and how it differs from the world.

    One error is drawn per episode (:meth:`dstenv.sensing.MapError.sample`); the label
    grid always comes from the true world. See :mod:`dstenv.sensing.mapmodel`.
    """
    return {
        # "map": the imperfect map below; "none": no map at all (every GIS cell
        # MapClass.NONE, a vacuous map input, as KITTI without an OSM file)
        "source": "map",
        "no_map_prob": 0.0,  # [-] chance per episode of "none" anyway (randomise map quality)
        "offset_std": 0.6,  # std of the localisation offset along ego x and ego y [m]
        "rotation_std": 0.015,  # std of the heading error [rad] (0.015 rad = 0.86 deg)
        "missing_building_prob": 0.12,  # [-] chance that a building is absent from the map
        "extra_building_rate": 0.08,  # [-] buildings in the map that do not exist, per true one
        "outline_shift_std": 0.7,  # std of the shift of a building outline [m]
        "outline_scale_std": 0.08,  # std of the relative scale error of an outline [-]
        # road surface in the map: "lanes" (street centre-line +- lanes x nominal
        # width / 2, as OSM) or "true" (the world's road raster)
        "road_width": "lanes",
        "nominal_lane_width": 3.0,  # [m] lane width a map assumes (OSM has no width tags)
        # what is neither road nor building in the map (sidewalks are not mapped):
        # "intermediate" (as the OSM loader) or "none" (no information)
        "background": "intermediate",
    }


def default_labels_config() -> dict[str, Any]:
    """The ``labels`` section: how ground truth is derived."""
    return {
        # an agent is "moving" when its speed exceeds this (the paper's 10 cm between
        # two 10 Hz measurements, per second), otherwise "static" [m/s]
        "moving_threshold": 0.1,
    }


def default_config() -> dict[str, dict[str, Any]]:
    """All sensing sections: ``{"lidar": ..., "gis": ..., "labels": ...}``."""
    return {
        "lidar": default_lidar_config(),
        "gis": default_gis_config(),
        "labels": default_labels_config(),
    }


_M = "m"

#: The ``lidar`` section.
_GROUND = {
    "iterations": between(1, 10_000),
    "sample": between(10, 1_000_000),
    "fit_range": between(1.0, 200.0, _M),
    "max_candidate_z": between(-10.0, 10.0, _M),
    "inlier_distance": between(0.0, 2.0, _M, lo_open=True),
    "max_tilt_deg": between(0.0, 45.0, "deg"),
    "ground_height": between(0.0, 2.0, _M),
    "min_obstacle_height": between(0.0, 5.0, _M),
    "max_obstacle_height": between(0.0, 50.0, _M),
    "ego_radius": between(0.0, 10.0, _M),
    "sector_deg": between(0.05, 45.0, "deg"),
    "bin_size": between(0.05, 20.0, _M),
    "max_slope": between(0.0, 2.0, "m/m"),
    "step_tolerance": between(0.0, 2.0, _M),
    "flat_spread": between(0.0, 5.0, _M),
    "max_drop_slope": between(0.0, 2.0, "m/m"),
    "drop_tolerance": between(0.0, 5.0, _M),
    "seed": between(0, 2**31 - 1),
}
_RAYS = {
    "max_range": between(1.0, 500.0, _M),
    "azimuth_bin_deg": between(0.01, 10.0, "deg"),
    "block_window_deg": between(0.0, 20.0, "deg"),
    "block_height": between(0.0, 10.0, _M),
}

#: The ``lidar`` section (beams and points per sweep bounded: a sweep's memory).
LIDAR = Section(default_lidar_config, {
    "model": one_of(*LIDAR_MODELS),
    "hdl64": {
        "channels": between(1, 512),
        "elevation_top": between(-90.0, 90.0, "deg"),
        "elevation_bottom": between(-90.0, 90.0, "deg"),
        "azimuth_step": between(0.01, 10.0, "deg"),
        "mount_height": between(0.1, 10.0, _M),
        "max_range": between(0.0, 500.0, _M, lo_open=True),
        "min_range": between(0.0, 50.0, _M),
        "range_noise": between(0.0, 5.0, _M),
        "dropout": PROB,
        "fade_range": between(0.0, 10_000.0, _M),
        "fade_sigma": between(0.01, 10.0),
        "vehicle_shape": one_of(*VEHICLE_SHAPES),
        "intensity_noise": between(0.0, 1.0),
        "spin_rate": between(0.0, 100.0, "Hz"),
        "channel_seed": between(0, 2**31 - 1),
        "ground": _GROUND,
        "rays": _RAYS,
    },
    "beams": between(1, 200_000),
    "fov": between(0.0, 360.0, "deg", lo_open=True),
    "max_range": between(0.0, 500.0, _M, lo_open=True),
    "range_noise": between(0.0, 5.0, _M),
    "dropout": PROB,
    "mount_x": between(-10.0, 10.0, _M),
    "mount_y": between(-10.0, 10.0, _M),
    "plane_height": between(0.0, 3.0, _M),
    "buildings": one_of("auto", "polygons", "raster"),
}, (("hdl64.elevation_top", lambda c: c["hdl64"]["elevation_top"] > c["hdl64"]["elevation_bottom"],
     "must be above hdl64.elevation_bottom"),
    ("hdl64.ground.max_obstacle_height",
     lambda c: c["hdl64"]["ground"]["min_obstacle_height"]
     < c["hdl64"]["ground"]["max_obstacle_height"],
     "must be above hdl64.ground.min_obstacle_height"),
    # the points of one sweep: channels x 360 / azimuth_step, bounded so a sweep fits
    ("hdl64.azimuth_step", lambda c: c["hdl64"]["channels"] * 360.0
     / c["hdl64"]["azimuth_step"] <= 5_000_000, "gives more than 5 million beams per sweep"),
))

#: The ``gis`` section.
GIS = Section(default_gis_config, {
    "source": one_of("map", "none"),
    "no_map_prob": PROB,
    "offset_std": between(0.0, 20.0, _M),
    "rotation_std": between(0.0, 0.5, "rad"),
    "missing_building_prob": PROB,
    "extra_building_rate": PROB,
    "outline_shift_std": between(0.0, 10.0, _M),
    "outline_scale_std": between(0.0, 0.3),
    "road_width": one_of("lanes", "true"),
    "nominal_lane_width": between(2.0, 5.0, _M),
    "background": one_of("intermediate", "none"),
})

#: The ``labels`` section.
LABELS = Section(default_labels_config, {
    "moving_threshold": between(0.0, 10.0, "m/s"),
})


def lidar_config(
    overrides: Mapping[str, Any] | None = None, where: str = "lidar"
) -> dict[str, Any]:
    """Merge and validate a ``lidar`` section (a :class:`~dstenv.config.Validated`
    section is returned as is).

    Raises:
        ConfigError: unknown key, wrong type, or a value out of range (named).
    """
    return section("lidar", overrides, where)


def gis_config(overrides: Mapping[str, Any] | None = None, where: str = "gis") -> dict[str, Any]:
    """Merge and validate a ``gis`` section (see :func:`lidar_config`)."""
    return section("gis", overrides, where)


def gis_is_exact(cfg: Mapping[str, Any]) -> bool:
    """The ``gis`` section describes the true map at the true pose (no error to draw)."""
    return (cfg["source"] == "map" and cfg["no_map_prob"] == 0 and cfg["road_width"] == "true"
            and cfg["background"] == "intermediate"
            and all(cfg[k] == 0 for k in ("offset_std", "rotation_std", "missing_building_prob",
                                          "extra_building_rate", "outline_shift_std",
                                          "outline_scale_std")))


def labels_config(
    overrides: Mapping[str, Any] | None = None, where: str = "labels"
) -> dict[str, Any]:
    """Merge and validate a ``labels`` section (see :func:`lidar_config`)."""
    return section("labels", overrides, where)
