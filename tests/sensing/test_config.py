"""Sensing configuration sections: defaults, validation."""

from __future__ import annotations

import pytest

from dstenv.config import ConfigError, merge_config
from dstenv.scenario_files import load_scenario
from dstenv.sensing import default_config
from dstenv.sensing.config import gis_config, gis_is_exact, labels_config, lidar_config


def test_defaults_follow_the_paper():
    cfg = default_config()
    assert set(cfg) == {"lidar", "gis", "labels"}
    assert cfg["lidar"]["beams"] == 1800 and cfg["lidar"]["fov"] == 360.0
    assert cfg["lidar"]["max_range"] == 80.0
    assert cfg["labels"]["moving_threshold"] == 0.1
    # the default map is imperfect (issue 12); the clean scenario keeps the exact one
    assert not gis_is_exact(cfg["gis"])
    assert gis_is_exact(gis_config(load_scenario("clean")["gis"]))
    # a fresh dict each call
    cfg["lidar"]["beams"] = 1
    assert default_config()["lidar"]["beams"] == 1800


def test_sections_merge_and_validate():
    assert lidar_config({"beams": 360.0})["beams"] == 360  # integral float accepted as int
    assert merge_config(default_config(), {"gis": {"offset_std": 0.2}})["gis"]["offset_std"] == 0.2
    msg = r"labels\.speed: unknown key 'speed'; allowed keys: moving_threshold"
    with pytest.raises(ConfigError, match=msg):
        labels_config({"speed": 1.0})
    with pytest.raises(ConfigError, match=r"lidar\.max_range: must be in \(0, 500\] m, got 0\.0"):
        lidar_config({"max_range": 0.0})
    with pytest.raises(ConfigError, match="fov"):
        lidar_config({"fov": 400.0})
    msg = r"gis\.missing_building_prob: must be in \[0, 1\], got -0\.1"
    with pytest.raises(ConfigError, match=msg):
        gis_config({"missing_building_prob": -0.1})
    with pytest.raises(ConfigError, match="expected a number"):
        gis_config({"offset_std": "big"})


def test_gis_and_plane_height_validation():
    with pytest.raises(ConfigError, match=r"gis\.source: unknown value 'osm'; allowed: map, none"):
        gis_config({"source": "osm"})
    with pytest.raises(ConfigError, match=r"gis\.road_width: unknown value"):
        gis_config({"road_width": "wide"})
    msg = r"gis\.nominal_lane_width: must be in \[2, 5\] m, got 9\.0"
    with pytest.raises(ConfigError, match=msg):
        gis_config({"nominal_lane_width": 9.0})
    with pytest.raises(ConfigError, match=r"gis\.no_map_prob: must be in \[0, 1\]"):
        gis_config({"no_map_prob": 2.0})
    with pytest.raises(ConfigError, match=r"lidar\.plane_height: must be in \[0, 3\] m"):
        lidar_config({"plane_height": 5.0})
