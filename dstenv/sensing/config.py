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

__all__ = [
    "default_config",
    "default_lidar_config",
    "default_gis_config",
    "default_labels_config",
    "lidar_config",
    "gis_config",
    "labels_config",
    "LIDAR",
    "GIS",
    "LABELS",
]


def default_lidar_config() -> dict[str, Any]:
    """The ``lidar`` section: a 2-D scanning LIDAR (a Velodyne sliced to the ground plane)."""
    return {
        "beams": 1800,  # number of beams per sweep [-] (0.2 deg spacing over 360 deg)
        "fov": 360.0,  # horizontal field of view [deg], centred on ego-forward
        "max_range": 80.0,  # [m]; beyond it a beam has no return
        "range_noise": 0.0,  # std of additive Gaussian range noise on returns [m]
        "dropout": 0.0,  # probability that a beam yields no measurement at all [-]
        "mount_x": 0.0,  # sensor position ahead of the ego centre [m]
        "mount_y": 0.0,  # sensor position left of the ego centre [m]
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


_M = "m"

#: The ``lidar`` section.
LIDAR = Section(default_lidar_config, {
    "beams": between(1, 200_000),
    "fov": between(0.0, 360.0, "deg", lo_open=True),
    "max_range": between(0.0, 500.0, _M, lo_open=True),
    "range_noise": between(0.0, 5.0, _M),
    "dropout": PROB,
    "mount_x": between(-10.0, 10.0, _M),
    "mount_y": between(-10.0, 10.0, _M),
    "buildings": one_of("auto", "polygons", "raster"),
})

#: The ``gis`` section.
GIS = Section(default_gis_config, {
    "offset_std": between(0.0, 20.0, _M),
    "rotation_std": between(0.0, 0.5, "rad"),
    "missing_building_prob": PROB,
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


def labels_config(
    overrides: Mapping[str, Any] | None = None, where: str = "labels"
) -> dict[str, Any]:
    """Merge and validate a ``labels`` section (see :func:`lidar_config`)."""
    return section("labels", overrides, where)
