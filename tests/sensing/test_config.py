"""Sensing configuration sections: defaults, validation."""

from __future__ import annotations

import pytest

from dstenv.config import ConfigError, merge_config
from dstenv.sensing import default_config
from dstenv.sensing.config import gis_config, labels_config, lidar_config


def test_defaults_follow_the_paper():
    cfg = default_config()
    assert set(cfg) == {"lidar", "gis", "labels"}
    assert cfg["lidar"]["beams"] == 1800 and cfg["lidar"]["fov"] == 360.0
    assert cfg["lidar"]["max_range"] == 80.0
    assert cfg["labels"]["moving_threshold"] == 0.1
    assert all(v == 0.0 for v in cfg["gis"].values())
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
