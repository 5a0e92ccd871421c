"""Default configuration of the sensing subsystem (sections ``lidar``, ``gis``, ``labels``).

Each section is a plain dict with units in comments (HighwayEnv style). Overrides are
validated with :func:`dstenv.config.merge_config`: an unknown key raises
:class:`dstenv.config.ConfigError` naming it and the allowed keys. The pipeline puts
these sections next to ``world``, ``grid`` and ``dst`` in its own config.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from dstenv.config import ConfigError, merge_config

__all__ = [
    "LIDAR_MODELS",
    "default_hdl64_config",
    "default_config",
    "default_lidar_config",
    "default_gis_config",
    "default_labels_config",
    "lidar_config",
    "gis_config",
    "labels_config",
]


#: ``lidar.model`` values: the fast 2-D scanner or the 3-D Velodyne HDL-64E-like one.
LIDAR_MODELS: tuple[str, ...] = ("2d", "hdl64")


def default_hdl64_config() -> dict[str, Any]:
    """The ``lidar.hdl64`` section: a spinning 64-channel LIDAR like KITTI's HDL-64E."""
    from dstenv.sensing.cloud import default_ground_config, default_ray_config

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
    """The ``gis`` section: errors of the map / localisation used for the GIS grid."""
    return {
        "offset_std": 0.0,  # std of the pose offset along ego x and ego y [m]
        "rotation_std": 0.0,  # std of the heading error [rad]
        "missing_building_prob": 0.0,  # probability that a building is absent from the map [-]
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


def _nonneg(cfg: Mapping[str, Any], key: str, where: str) -> None:
    if not cfg[key] >= 0:
        raise ConfigError(f"{where}.{key}: must be >= 0, got {cfg[key]!r}")


def _prob(cfg: Mapping[str, Any], key: str, where: str) -> None:
    if not 0.0 <= cfg[key] <= 1.0:
        raise ConfigError(f"{where}.{key}: must lie in [0, 1], got {cfg[key]!r}")


def lidar_config(
    overrides: Mapping[str, Any] | None = None, where: str = "lidar"
) -> dict[str, Any]:
    """Merge and validate a ``lidar`` section.

    Raises:
        ConfigError: unknown key, wrong type, or a value out of range (named).
    """
    cfg = merge_config(default_lidar_config(), overrides, where)
    if cfg["beams"] < 1:
        raise ConfigError(f"{where}.beams: must be >= 1, got {cfg['beams']!r}")
    if not 0.0 < cfg["fov"] <= 360.0:
        raise ConfigError(f"{where}.fov: must lie in (0, 360] deg, got {cfg['fov']!r}")
    if not cfg["max_range"] > 0.0:
        raise ConfigError(f"{where}.max_range: must be > 0 m, got {cfg['max_range']!r}")
    _nonneg(cfg, "range_noise", where)
    _prob(cfg, "dropout", where)
    if not 0.0 <= cfg["plane_height"] <= 3.0:
        raise ConfigError(
            f"{where}.plane_height: must lie in [0, 3] m, got {cfg['plane_height']!r}"
        )
    if cfg["model"] not in LIDAR_MODELS:
        raise ConfigError(f"{where}.model: unknown value {cfg['model']!r}; "
                          f"allowed: {', '.join(LIDAR_MODELS)}")
    h = cfg["hdl64"]
    if h["channels"] < 1 or not h["elevation_top"] > h["elevation_bottom"]:
        raise ConfigError(f"{where}.hdl64: need channels >= 1 and elevation_top > "
                          f"elevation_bottom, got {h['channels']}, {h['elevation_top']}, "
                          f"{h['elevation_bottom']}")
    for key in ("azimuth_step", "mount_height", "max_range"):
        if not h[key] > 0:
            raise ConfigError(f"{where}.hdl64.{key}: must be > 0, got {h[key]!r}")
    for key in ("min_range", "range_noise", "intensity_noise", "spin_rate"):
        _nonneg(h, key, f"{where}.hdl64")
    _prob(h, "dropout", f"{where}.hdl64")
    allowed = ("auto", "polygons", "raster")
    if cfg["buildings"] not in allowed:
        raise ConfigError(
            f"{where}.buildings: unknown value {cfg['buildings']!r}; allowed: {', '.join(allowed)}"
        )
    return cfg


def gis_config(overrides: Mapping[str, Any] | None = None, where: str = "gis") -> dict[str, Any]:
    """Merge and validate a ``gis`` section (see :func:`lidar_config`)."""
    cfg = merge_config(default_gis_config(), overrides, where)
    _nonneg(cfg, "offset_std", where)
    _nonneg(cfg, "rotation_std", where)
    _prob(cfg, "missing_building_prob", where)
    return cfg


def labels_config(
    overrides: Mapping[str, Any] | None = None, where: str = "labels"
) -> dict[str, Any]:
    """Merge and validate a ``labels`` section (see :func:`lidar_config`)."""
    cfg = merge_config(default_labels_config(), overrides, where)
    _nonneg(cfg, "moving_threshold", where)
    return cfg
