"""Validated config merging and scenario loading."""

import pytest

from dstenv.config import ConfigError, load_scenario, merge_config

DEFAULTS = {"world": {"lanes": 2, "speed": 10.0, "name": "city", "flag": False}, "seed": 0}


def test_merge_overrides_and_keeps_defaults():
    out = merge_config(DEFAULTS, {"world": {"lanes": 3}})
    assert out["world"] == {"lanes": 3, "speed": 10.0, "name": "city", "flag": False}
    assert DEFAULTS["world"]["lanes"] == 2  # not modified


def test_unknown_key_names_it_and_allowed_keys():
    with pytest.raises(ConfigError, match=r"config\.world\.lane: unknown key 'lane'; allowed keys: flag, lanes, name, speed"):
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


def test_scenario_file_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[world]\nlanes = \n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_scenario(bad, DEFAULTS)
    typo = tmp_path / "typo.toml"
    typo.write_text('description = "x"\n[world]\nlanse = 2\n')
    with pytest.raises(ConfigError, match=r"typo\.toml\.world\.lanse: unknown key"):
        load_scenario(typo, DEFAULTS)
    with pytest.raises(ConfigError, match="unknown scenario 'nope'"):
        load_scenario("nope", DEFAULTS)
    with pytest.raises(ConfigError, match="not found"):
        load_scenario(tmp_path / "missing.toml", DEFAULTS)


def test_scenario_file_merges(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text('description = "two lanes"\n[world]\nlanes = 3\n')
    assert load_scenario(good, DEFAULTS)["world"]["lanes"] == 3
