"""Every shipped scenario validates against the full default config and builds a world."""

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.scenario_files import list_scenarios, load_scenario, scenario_path
from dstenv.sim import World
from dstenv.sim import default_config as world_defaults

REQUIRED = {"default", "dense", "suburb", "parking", "osm"}


def _defaults():
    try:
        from dstenv.pipeline import default_config
    except ImportError:  # pipeline not part of this build: validate the world section only
        return {"world": world_defaults()}
    return default_config()


def test_required_scenarios_are_shipped():
    assert REQUIRED <= set(list_scenarios())


@pytest.mark.parametrize("name", sorted(list_scenarios()))
def test_scenario_loads_and_builds_a_world(name):
    path = scenario_path(name)
    cfg = load_scenario(name, _defaults())
    w = World(cfg["world"], seed=0, base_dir=path.parent)
    for _ in range(5):
        w.step()
    assert len(w.agents) > 0 and w.map.raster.size > 0
    assert np.isfinite(w.ego_pose).all()


def test_scenarios_differ_as_described():
    cfg = {n: load_scenario(n, _defaults())["world"] for n in ("dense", "suburb", "parking")}
    assert cfg["dense"]["traffic"]["pedestrians"] > cfg["suburb"]["traffic"]["pedestrians"]
    assert cfg["suburb"]["map"]["setback_min"] > cfg["dense"]["map"]["setback_max"]
    assert cfg["parking"]["map"]["parking_prob"] == 1.0
    assert load_scenario("osm", _defaults())["world"]["map"]["kind"] == "osm"


def test_unknown_key_is_named_with_the_allowed_keys(tmp_path):
    bad = tmp_path / "typo.toml"
    bad.write_text('[world.traffic]\npedestrians = 3\nbicycles = 2\n')
    with pytest.raises(ConfigError, match=r"world\.traffic\.bicycles: unknown key 'bicycles'; "
                                          r"allowed keys: .*cyclists.*pedestrians"):
        load_scenario(bad, _defaults())


def test_a_users_osm_file_is_found_beside_the_scenario(tmp_path, monkeypatch):
    folder = tmp_path / "sc"
    folder.mkdir()
    (folder / "town.osm").write_text("<osm/>")
    (folder / "rel.toml").write_text('[world.map]\nkind = "osm"\nosm_file = "town.osm"\n')
    (folder / "gone.toml").write_text('[world.map]\nkind = "osm"\nosm_file = "nope.osm"\n')
    monkeypatch.chdir(tmp_path)  # not the scenario's folder
    cfg = load_scenario(folder / "rel.toml", _defaults())
    assert cfg["world"]["map"]["osm_file"] == str((folder / "town.osm").resolve())
    # not beside it: left as written (the current folder, then the shipped maps)
    assert load_scenario(folder / "gone.toml", _defaults())["world"]["map"]["osm_file"] == (
        "nope.osm")
    # the shipped OSM scenario keeps its relative path: the same config on every install
    shipped = load_scenario("osm", _defaults())["world"]["map"]["osm_file"]
    assert not shipped.startswith("/")


def test_a_scenario_that_is_not_utf8_is_one_line(tmp_path):
    bad = tmp_path / "latin.toml"
    bad.write_bytes(b'description = "caf\xe9"\n')
    with pytest.raises(ConfigError, match=r"latin\.toml: not UTF-8 text at byte 18"):
        load_scenario(bad, _defaults())


def test_a_folder_given_as_scenario_file_is_named_as_one(tmp_path):
    from dstenv.config import ConfigError

    with pytest.raises(ConfigError, match=r"is a folder, not a file; give an existing \.toml"):
        scenario_path(str(tmp_path) + "/")
    with pytest.raises(ConfigError, match=r"not found: no such file"):
        scenario_path(tmp_path / "nope.toml")
