"""``dstenv generate`` / ``dstenv info`` through the real command line."""

from __future__ import annotations

import json

import pytest

from dstenv.cli import main
from dstenv.config import CLIError
from dstenv.data.cli import parse_set
from dstenv.data.generate import GenerateSpec, generate


def test_parse_set():
    assert parse_set(["world.cars=10", "lidar.fov=180.0", "source=highway", "a.b.c=true"]) == {
        "world": {"cars": 10}, "lidar": {"fov": 180.0}, "source": "highway",
        "a": {"b": {"c": True}}}
    with pytest.raises(CLIError, match="expected SECTION.KEY=VALUE"):
        parse_set(["world.cars"])
    # a key below a value an earlier item set: one line naming both (was a traceback)
    with pytest.raises(CLIError, match="world is already set to a value by --set 'world=5'"):
        parse_set(["world=5", "world.traffic.cars=3"])
    with pytest.raises(CLIError, match="world.a is already set .* --set 'world={a=1}'"):
        parse_set(["world={a=1}", "world.a.b=2"])
    assert parse_set(["world={a={c=1}}", "world.a.b=2"]) == {"world": {"a": {"c": 1, "b": 2}}}


def test_parse_set_reads_json_objects_and_arrays_as_results_json_prints_them():
    assert parse_set(['model_kwargs={"unet-light": {"betp_skip": 1.0}}',
                      "model_kwargs.fcn={base=8}", 'search.values=[0.25, 0.5]',
                      'tune.params={"alpha": 0.5, "delta_inc": 0.4}']) == {
        "model_kwargs": {"unet-light": {"betp_skip": 1.0}, "fcn": {"base": 8}},
        "search": {"values": [0.25, 0.5]}, "tune": {"params": {"alpha": 0.5, "delta_inc": 0.4}}}
    # neither TOML nor JSON: the text itself, which the config check then refuses by key
    assert parse_set(["a.b={oops"]) == {"a": {"b": "{oops"}}
    from dstenv.config import ConfigError, merge_config

    with pytest.raises(ConfigError, match="model_kwargs: expected a table .* a JSON object"):
        merge_config({"model_kwargs": {}}, parse_set(["model_kwargs={oops"]), "benchmark")


def test_info_prints_paper_reference(tmp_path, capsys, fake_pipeline):
    spec = GenerateSpec(config={"grid": {"height": 8, "width": 6, "cell_size": 0.5}}, frames=10,
                        frames_per_shard=4, episode_length=5, stride=2, warmup=0)
    generate(spec, tmp_path, progress=False)
    assert main(["info", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "frames    10 in 4 shards: test 1 frame / 1 shard, train 8 frames / 2 shards" in text
    assert "grid      8 x 6 cells of 0.5 m" in text
    assert "static" in text and "0.09%" in text and "0.26%" in text
    assert main(["info", str(tmp_path), "--json", "--verify", "hash"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["frames"] == 10 and s["shards"] == 4
    # the manifest's own path names its dataset
    assert main(["info", str(tmp_path / "manifest.json"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["frames"] == 10
    # --verify none reads the manifest as it stands: a missing entry is one line
    m = json.loads((tmp_path / "manifest.json").read_text())
    m.pop("class_frequencies")
    (tmp_path / "manifest.json").write_text(json.dumps(m))
    assert main(["info", str(tmp_path), "--verify", "none"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a missing or malformed entry" in err
    assert main(["info", str(tmp_path)]) == 2
    assert "'class_frequencies' is None" in capsys.readouterr().err
    assert sum(s["class_frequencies"].values()) == pytest.approx(1.0)
    assert s["bytes_per_frame"] == pytest.approx(s["bytes"] / 10)
    assert main(["info", str(tmp_path / "train" / "shard-00000.h5")]) == 0
    assert "4 in 1 shard:" in capsys.readouterr().out


def test_info_into_a_closed_pipe_is_quiet(tmp_path, fake_pipeline):
    # `dstenv info DIR | head -1`: the reader leaves early; no "Broken pipe" error line
    import subprocess
    import sys

    spec = GenerateSpec(config={"grid": {"height": 8, "width": 6, "cell_size": 0.5}}, frames=4,
                        frames_per_shard=4, episode_length=5, stride=2, warmup=0)
    generate(spec, tmp_path, progress=False)
    proc = subprocess.Popen([sys.executable, "-m", "dstenv.cli", "info", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # before the child writes its first line
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert proc.wait(timeout=120) in (0, 141) and "Broken pipe" not in err, err


def test_info_errors_are_one_line(tmp_path, capsys, fake_pipeline):
    assert main(["info", str(tmp_path / "nope")]) == 2
    assert capsys.readouterr().err.strip().endswith("nope: no such file or directory")
    assert main(["info", str(tmp_path)]) == 2
    assert "no manifest.json and no shards" in capsys.readouterr().err
    spec = GenerateSpec(config={"grid": {"height": 8, "width": 6, "cell_size": 0.5}}, frames=4,
                        frames_per_shard=2, episode_length=5, stride=2, warmup=0, split="val")
    generate(spec, tmp_path, progress=False)
    (tmp_path / "val" / "shard-00001.h5").unlink()
    assert main(["info", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "lists val/shard-00001.h5 but that file is missing" in err


@pytest.mark.parametrize("grid", ["64x", "x64", "64x64x2", "sixty", "1x64"])
def test_generate_grid_must_be_n_or_hxw(tmp_path, capsys, grid):
    with pytest.raises(SystemExit) as exc:
        main(["generate", "--frames", "2", "--grid", grid, "--out", str(tmp_path / "o")])
    assert exc.value.code == 2 and "--grid" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("flags", [["--grid", "64", "--set", "grid.height=-1"],
                                   ["--grid", "32x48", "--set", "grid.width=32"],
                                   ["--cell-size", "0.5", "--set", "grid.cell_size=0.2"]])
def test_generate_flag_and_set_must_agree(tmp_path, capsys, flags):
    # before, --grid / --cell-size silently replaced the --set value
    assert main(["generate", "--frames", "2", "--out", str(tmp_path / "o"), *flags]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "disagree: give one" in err and flags[0] in err
    assert not (tmp_path / "o").exists()


def test_generate_refuses_an_empty_out(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["generate", "--frames", "2", "--out", ""]) == 2
    assert "--out: empty" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_generate_names_set_in_config_errors(tmp_path, capsys):
    """A bad ``--set`` value is named as render names it (the layer, then the key)."""
    assert main(["generate", "--frames", "2", "--out", str(tmp_path / "g"), "--set",
                 "world.dt=-1"]) == 2
    assert "error: --set: world.dt: must be in (0, 1] s" in capsys.readouterr().err
    assert main(["generate", "--frames", "2", "--out", str(tmp_path / "g"), "--set",
                 "world.dtt=1"]) == 2
    assert "error: --set: world.dtt: unknown key 'dtt'" in capsys.readouterr().err
    assert not (tmp_path / "g").exists()


def test_a_bad_type_in_set_or_a_scenario_file_names_the_layer_then_the_key(tmp_path, capsys):
    from dstenv.cli import main

    out = str(tmp_path / "d")
    assert main(["generate", "--frames", "2", "--out", out, "--set", "world.map.pool=1.5"]) == 2
    assert "error: --set: world.map.pool: expected an integer, got 1.5" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text('[world]\ndt = "x"\n')
    assert main(["generate", "--frames", "2", "--out", out, "--scenario", str(bad)]) == 2
    assert f"error: {bad}: world.dt: expected a number, got 'x'" in capsys.readouterr().err


def test_info_on_a_partial_shard_says_what_it_is(tmp_path, capsys, fake_pipeline):
    assert main(["generate", "--frames", "2", "--split", "val", "--quiet", "--workers", "1",
                 "--out", str(tmp_path / "d"), "--set", "grid.height=16",
                 "--set", "grid.width=16"]) == 0
    shard = next((tmp_path / "d").rglob("*.h5"))
    partial = shard.with_name(shard.name + ".partial")
    partial.write_bytes(shard.read_bytes())  # as a killed run leaves it
    assert main(["info", str(partial)]) == 0
    err = capsys.readouterr().err
    assert "is a shard being written, or left by a run that was killed" in err
