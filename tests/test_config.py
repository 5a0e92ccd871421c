"""Validated config merging and scenario loading."""

import numpy as np
import pytest

from pathlib import Path

from dstenv.config import ConfigError, merge_config
from dstenv.scenario_files import load_scenario, scenario_path

DEFAULTS = {"world": {"lanes": 2, "speed": 10.0, "name": "city", "flag": False}, "seed": 0}


def test_merge_overrides_and_keeps_defaults():
    out = merge_config(DEFAULTS, {"world": {"lanes": 3}})
    assert out["world"] == {"lanes": 3, "speed": 10.0, "name": "city", "flag": False}
    assert DEFAULTS["world"]["lanes"] == 2  # not modified


def test_unknown_key_names_it_and_allowed_keys():
    msg = r"config\.world\.lane: unknown key 'lane'; allowed keys: flag, lanes, name, speed"
    with pytest.raises(ConfigError, match=msg):
        merge_config(DEFAULTS, {"world": {"lane": 3}})


@pytest.mark.parametrize(
    "override, match",
    [
        ({"world": 3}, "expected a table"),
        ({"world": {"lanes": "two"}}, "expected a number"),
        ({"world": {"lanes": 2.5}}, "expected an integer"),
        ({"world": {"flag": 1}}, "expected true/false"),
        ({"world": {"name": 1}}, "expected a string"),
    ],
)
def test_type_errors(override, match):
    with pytest.raises(ConfigError, match=match):
        merge_config(DEFAULTS, override)


def test_int_promotes_to_float():
    assert merge_config(DEFAULTS, {"world": {"speed": 12}})["world"]["speed"] == 12.0
    # numpy scalars are numbers (they were refused as "expected a number, got np.int64(84)")
    got = merge_config(DEFAULTS, {"world": {"speed": np.float32(2.5)}})["world"]["speed"]
    assert got == 2.5 and type(got) is float
    lanes = merge_config(DEFAULTS, {"world": {"lanes": np.int64(3)}})["world"]["lanes"]
    assert lanes == 3 and type(lanes) is int


def test_scenario_file_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[world]\nlanes = \n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_scenario(bad, DEFAULTS)
    typo = tmp_path / "typo.toml"
    typo.write_text('description = "x"\n[world]\nlanse = 2\n')
    with pytest.raises(ConfigError, match=r"typo\.toml: world\.lanse: unknown key"):
        load_scenario(typo, DEFAULTS)
    with pytest.raises(ConfigError, match="unknown scenario 'nope'"):
        load_scenario("nope", DEFAULTS)
    with pytest.raises(ConfigError, match="not found"):
        load_scenario(tmp_path / "missing.toml", DEFAULTS)


def test_scenario_file_merges(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text('description = "two lanes"\n[world]\nlanes = 3\n')
    assert load_scenario(good, DEFAULTS)["world"]["lanes"] == 3


# -- the configuration gate ------------------------------------------------------------
from dstenv.config import Validated, build_config, section  # noqa: E402


@pytest.mark.parametrize("override, message", [
    ({"gis": {"offset_std": -0.5}}, r"gis\.offset_std: must be in \[0, 20\] m, got -0\.5"),
    ({"gis": {"missing_building_prob": -0.1}}, r"gis\.missing_building_prob: must be in \[0, 1\]"),
    ({"labels": {"moving_threshold": -1.0}}, r"labels\.moving_threshold: must be in \[0, 10\]"),
    ({"world": {"traffic": {"cars": 100000}}}, r"world\.traffic\.cars: must be in \[0, 500\]"),
    ({"world": {"map": {"lane_width": 0.0}}},
     r"world\.map\.lane_width: must be in \[2\.5, 4\.5\] m"),
    ({"world": {"ego": {"max_speed": float("nan")}}}, r"world\.ego\.max_speed: must be in"),
    ({"grid": {"cell_size": float("inf")}}, r"grid\.cell_size: must be in \[0\.01, 10\] m"),
    ({"grid": {"height": 100000}}, r"grid\.height: must be in \[2, 4096\] cells"),
    ({"dst": {"alpha": 1.5}}, r"dst\.alpha: must be in \[0, 1\], got 1\.5"),
    ({"lidar": {"buildings": "voxels"}}, r"lidar\.buildings: unknown value 'voxels'; allowed"),
    ({"world": {"map": {"lanes_min": 3, "lanes_max": 2}}}, r"world\.map\.lanes_max: must be >="),
    # below the outer streets' sidewalks the ego and agents were placed off the map
    ({"world": {"map": {"margin": 3.0}}}, r"world\.map\.margin: must reach past the outer"),
    # 40 x 40 blocks of 1 km: a 46.7 GiB raster, refused by name instead of MemoryError
    ({"world": {"map": {"blocks_x": 40, "blocks_y": 40, "block_min": 1000.0,
                        "block_max": 1000.0}}}, r"world\.map\.blocks_x: .* over 10\^9 cells"),
    ({"world": {"map": {"pool": 5000}}}, r"world\.map\.pool: must be in \[0, 1000\]"),
    ({"world": {"map": {"curb_strip_width": 0.0, "sidewalk_width": 1.0, "curb_strip_jitter": 0.0,
                        "sidewalk_jitter": 0.0}}}, r"world\.map\.sidewalk_width: with curb"),
    ({"highway": {"env_config": {"other_vehicles_type": "evilmod.V"}}},
     r"highway\.env_config\.other_vehicles_type: not an allowed highway-env key"),
    ({"highway": {"env_config": {"duration": "40"}}}, r"highway\.env_config\.duration: must be"),
])
def test_gate_rejects_bad_values_by_name(override, message):
    with pytest.raises(ConfigError, match=message):
        build_config(None, override)


def test_gate_merges_scenario_then_overrides_in_order():
    cfg = build_config("dense", {"grid": {"height": 64}}, ("mine", {"grid": {"height": 32}}))
    assert isinstance(cfg, Validated) and isinstance(cfg["world"], Validated)
    assert cfg["grid"]["height"] == 32
    with pytest.raises(ConfigError, match=r"^mine\.grid\.heigth: unknown key"):
        build_config(None, ("mine", {"grid": {"heigth": 1}}))


def test_section_returns_validated_input_unchanged():
    cfg = build_config()
    assert section("world", cfg["world"]) is cfg["world"]
    fresh = section("world", {"traffic": {"cars": 3}})
    assert fresh["traffic"]["cars"] == 3 and fresh["map"]["kind"] == "procedural"


def test_shipped_scenario_wins_over_a_folder_of_the_same_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dense").mkdir()
    assert scenario_path("dense").parent.name == "scenarios"
    (tmp_path / "dense.toml").write_text("[grid]\nheight = 40\n")
    assert scenario_path("./dense.toml") == Path("./dense.toml")
    assert build_config("./dense.toml")["grid"]["height"] == 40


def test_free_form_table_rejects_a_scalar():
    # data.overrides = {} by default: any keys, but it must be a table (a JSON string
    # given to --set used to reach the benchmark and fail there with an AttributeError)
    from dstenv.config import ConfigError, merge_config

    assert merge_config({"o": {}}, {"o": {"x": {"y": 1}}}) == {"o": {"x": {"y": 1}}}
    with pytest.raises(ConfigError, match=r"^bench\.o: expected a table .*got '\{\"p\": 1\}'"):
        merge_config({"o": {}}, {"o": '{"p": 1}'}, "bench")


def test_a_bad_value_names_where_it_was_written(tmp_path):
    """Range errors (checked on the merged configuration) name the layer that set the
    key last: the scenario file, or the override's label."""
    f = tmp_path / "neg.toml"
    f.write_text("[world]\ndt = -0.1\n")
    with pytest.raises(ConfigError, match=r"neg\.toml: world\.dt: must be in \(0, 1\]"):
        build_config(f)
    with pytest.raises(ConfigError, match=r"^--set: world\.dt: must be in \(0, 1\] s, got -1"):
        build_config(f, ("--set", {"world": {"dt": -1.0}}))  # the last layer to set it
    with pytest.raises(ConfigError, match=r"^--set: world\.dt"):
        build_config(None, ("--set", {"world": {"dt": 5.0}}))
