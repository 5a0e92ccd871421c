"""Hostile input: files and values that must give a one-line error, never a crash,
a hang, runaway memory or silently wrong data (one test per attack)."""

from __future__ import annotations

import argparse
import bz2

import pytest

from dstenv.config import ConfigError, build_config
from dstenv.kitti.readers import KittiError, read_calib, read_labels, read_oxts
from dstenv.sim.osm import load_osm
from dstenv.sim.osm_xml import OSM_LIMITS
from shared_data import SHARED_DATA

KITTI = SHARED_DATA / "kitti-tracking"
OSM = """<?xml version="1.0"?>
<osm version="0.6">
 <bounds minlat="49.0" minlon="8.4" maxlat="49.001" maxlon="8.401"/>
 <node id="1" lat="49.0002" lon="8.4002"/><node id="2" lat="49.0008" lon="8.4002"/>
 <way id="10"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/>{lanes}</way>
</osm>
"""


# -- OpenStreetMap -------------------------------------------------------------------
def test_osm_bomb_is_stopped_at_the_size_limit(tmp_path, monkeypatch):
    monkeypatch.setitem(OSM_LIMITS, "bytes", 1 << 20)
    body = b'<osm version="0.6">' + b"<!-- padding -->" * 200_000 + b"</osm>"
    path = tmp_path / "bomb.osm.bz2"
    path.write_bytes(bz2.compress(body, 9))
    assert path.stat().st_size < 5_000  # a few KB inflating to 3 MB
    with pytest.raises(ValueError, match=r"bomb\.osm\.bz2: more than 1 MiB of XML"):
        load_osm(path)


def test_osm_entity_declarations_are_refused(tmp_path):
    path = tmp_path / "lol.osm"
    path.write_text('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol">]>'
                    '<osm><node id="1" lat="0" lon="0"/></osm>')
    with pytest.raises(ValueError, match="DTD or entity declaration"):
        load_osm(path)


def test_osm_bounds_spanning_the_globe_are_refused(tmp_path):
    path = tmp_path / "globe.osm"
    path.write_text(OSM.format(lanes="").replace(
        'minlat="49.0" minlon="8.4" maxlat="49.001" maxlon="8.401"',
        'minlat="-80" minlon="-170" maxlat="80" maxlon="170"'))
    with pytest.raises(ValueError, match=r"globe\.osm: the map spans .* km"):
        load_osm(path)


def test_osm_absurd_lane_counts_are_clamped(tmp_path):
    path = tmp_path / "lanes.osm"
    path.write_text(OSM.format(lanes='<tag k="lanes" v="1e9"/><tag k="width" v="nan"/>'))
    wm = load_osm(path, resolution=0.5)
    assert wm.raster.size < 1_000_000
    n_lanes = len(wm.lanes)
    assert 0 < n_lanes <= 2 * OSM_LIMITS["lanes"] + 8


# -- KITTI ---------------------------------------------------------------------------
needs_kitti = pytest.mark.skipif(not KITTI.is_dir(), reason="shared KITTI sample absent")


@needs_kitti
def test_kitti_calibration_with_nan_is_refused(tmp_path):
    text = (KITTI / "training" / "calib" / "0003.txt").read_text().splitlines()
    text = [ln if not ln.startswith("Tr_velo_cam") else
            "Tr_velo_cam " + " ".join(["nan"] * 12) for ln in text]
    (tmp_path / "c.txt").write_text("\n".join(text) + "\n")
    with pytest.raises(KittiError, match=r"c\.txt: Tr_velo_cam holds non-finite values"):
        read_calib(tmp_path / "c.txt")


@needs_kitti
def test_kitti_calibration_that_is_no_rotation_is_refused(tmp_path):
    text = (KITTI / "training" / "calib" / "0003.txt").read_text().splitlines()
    text = [ln if not ln.startswith("R_rect") else "R_rect 2 0 0 0 2 0 0 0 2" for ln in text]
    (tmp_path / "c.txt").write_text("\n".join(text) + "\n")
    with pytest.raises(KittiError, match="R_rect is not a rotation"):
        read_calib(tmp_path / "c.txt")


@needs_kitti
@pytest.mark.parametrize("col, value, message", [
    (10, "nan", "non-finite value"), (10, "250", "implausible box size"),
    (13, "1e6", "more than 500 m"),
])
def test_kitti_absurd_boxes_are_refused(tmp_path, col, value, message):
    lines = (KITTI / "training" / "label_02" / "0003.txt").read_text().splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.split()[2] == "Car")
    tok = lines[i].split()
    tok[col] = value
    lines[i] = " ".join(tok)
    (tmp_path / "l.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(KittiError, match=message):
        read_labels(tmp_path / "l.txt")


@needs_kitti
def test_kitti_oxts_jump_is_refused(tmp_path):
    lines = (KITTI / "training" / "oxts" / "0003.txt").read_text().splitlines()
    tok = lines[5].split()
    tok[0] = str(float(tok[0]) + 0.9)  # 100 km north
    lines[5] = " ".join(tok)
    (tmp_path / "o.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(KittiError, match=r"o\.txt:6: position jumps \d+ m"):
        read_oxts(tmp_path / "o.txt")


@needs_kitti
@pytest.mark.parametrize("args, message", [
    (["--sequences", "0003,3"], "sequence 0003 listed twice"),
    (["--sequences", "0003", "--split", "../x"], "a split is a plain name"),
])
def test_kitti_convert_arguments(tmp_path, capsys, args, message):
    from dstenv.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["kitti", "convert", "--root", str(KITTI), "--out", str(tmp_path / "o"), *args])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


# -- numbers and checkpoints -----------------------------------------------------------
@pytest.mark.parametrize("override", [
    {"grid": {"cell_size": float("inf")}}, {"grid": {"cell_size": 1e-9}},
    {"world": {"traffic": {"speed_limit": -3.0}}}, {"world": {"map": {"lane_width": 0.0}}},
    {"reward": {"collision": float("nan")}}, {"world": {"traffic": {"cars": 3000}}},
    {"world": {"map": {"blocks_x": 300}}},
])
def test_numbers_without_bounds_are_rejected_at_construction(override):
    import gymnasium as gym

    import dstenv  # noqa: F401

    with pytest.raises(ConfigError):
        gym.make("DSTGrid-v0", config=override)
    if "reward" not in override:
        with pytest.raises(ConfigError):
            build_config(None, override)


def test_huge_seed_is_rejected_before_any_work(tmp_path, capsys):
    from dstenv.cli import main

    assert main(["generate", "--frames", "4", "--seed", str(2**64), "--quiet",
                 "--out", str(tmp_path / "d")]) == 2
    assert "seed must be in [0, 2**63)" in capsys.readouterr().err
    assert not list((tmp_path / "d").rglob("*.h5"))


@pytest.mark.parametrize("content, message", [
    (b"", "cannot read checkpoint: the file is empty"),
    (b"not a zip", "cannot read checkpoint: not a PyTorch file"),
    (b'{"format": "dstenv-manifest"}', "not a PyTorch file"),  # train --init manifest.json
    ("pickle", "holds objects other than tensors; refused"),  # not torch's "trust it" advice
])
def test_broken_checkpoints_are_one_line_errors(tmp_path, content, message):
    import torch

    from dstenv.segment.checkpoint import load_segmenter

    path = tmp_path / "m.pt"
    if content == "pickle":
        torch.save({"model": argparse.Namespace(a=1)}, path)
    else:
        path.write_bytes(content)
    with pytest.raises(ValueError, match=message) as err:
        load_segmenter(path)
    assert "\n" not in str(err.value) and "trust" not in str(err.value)


def test_checkpoint_without_spec_or_with_other_weights(tmp_path):
    from dstenv.segment.checkpoint import load_segmenter, save_checkpoint
    from dstenv.segment.segmenters import TorchSegmenter

    save_checkpoint(tmp_path / "a.pt", {"model": {}})
    with pytest.raises(ValueError, match=r"a\.pt: checkpoint has no valid 'spec'"):
        load_segmenter(tmp_path / "a.pt")
    seg = TorchSegmenter("unet-light", {"base": 4, "depth": 2}, in_channels=10)
    spec = {**seg.spec(), "in_channels": 5}
    save_checkpoint(tmp_path / "b.pt", {"spec": spec, "model": seg.model.state_dict()})
    with pytest.raises(ValueError, match=r"b\.pt: weights do not fit a unet-light with 5"):
        load_segmenter(tmp_path / "b.pt")


def test_failed_reset_config_leaves_the_env_working():
    import gymnasium as gym

    import dstenv  # noqa: F401

    env = gym.make("DSTGrid-v0", config={"grid": {"height": 40, "width": 40}})
    obs, _ = env.reset(seed=0)
    space = env.observation_space
    with pytest.raises(ConfigError):
        env.reset(options={"config": {"observation": {"type": "pignistic"},
                                      "grid": {"cell_size": -1.0}}})
    with pytest.raises(ConfigError):  # builds, then fails on the first episode
        env.reset(options={"config": {"world": {"map": {"kind": "osm"}}}})
    obs, _ = env.reset(seed=1)
    assert env.observation_space == space and space.contains(obs)
    obs, *_ = env.step(1)
    assert space.contains(obs)
    env.close()



def test_deeply_nested_toml_is_a_named_error(tmp_path):
    from dstenv.scenario_files import load_scenario

    path = tmp_path / "deep.toml"
    path.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ConfigError, match=r"deep\.toml: invalid TOML: nested too deeply"):
        load_scenario(path)
