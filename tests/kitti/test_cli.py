"""``dstenv kitti convert|render|evaluate`` end to end on the synthetic sequence."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dstenv.cli import main
from dstenv.data import ShardDataset
from dstenv.data.manifest import load_manifest
from dstenv.data.shards import ShardReader

from .conftest import FIXTURES


def _convert(tiny_root, out, *extra):
    return main(["kitti", "convert", "--root", str(tiny_root), "--sequences", "0001",
                 "--stride", "2", "--warmup", "0", "--out", str(out), *extra])


def test_convert_writes_shards_and_manifest(tiny_root, tmp_path, capsys):
    out = tmp_path / "ds"
    assert _convert(tiny_root, out) == 0
    text = capsys.readouterr().out
    assert "no map: GIS grid vacuous" in text and "3 frames" in text
    manifest = load_manifest(out, verify="hash")
    assert manifest["frames"] == 3 and list(manifest["splits"]) == ["test"]
    with ShardReader(out / "test" / "kitti-0001.h5") as r:
        assert r.attrs["source"] == "kitti" and r.attrs["map"] == "none"
        assert r.attrs["config"]["stride"] == 2
        assert [int(r.get(i, ["step"])["step"]) for i in range(len(r))] == [0, 2, 4]
    ds = ShardDataset(out, split="test")
    item = ds[1]
    assert item["x"].shape == (10, 256, 256) and item["labels"].shape == (256, 256)
    assert set(np.unique(item["labels"].numpy())) <= {0, 3, 4, 255}
    # rerunning into the same directory replaces the shard (same bytes: deterministic)
    before = (out / "test" / "kitti-0001.h5").read_bytes()
    assert _convert(tiny_root, out) == 0
    assert (out / "test" / "kitti-0001.h5").read_bytes() == before
    # other settings into the same directory: refused, the shard kept
    capsys.readouterr()
    for extra in (("--masses",), ("--label-rule", "paper")):
        assert _convert(tiny_root, out, *extra) == 2
        err = capsys.readouterr().err
        assert "kitti-0001.h5 was converted with other settings" in err, err
        assert len(err.strip().splitlines()) == 1
        assert (out / "test" / "kitti-0001.h5").read_bytes() == before
    # the setting that differs is named by its key, not by two whole configurations
    assert _convert(tiny_root, out, "--stride", "3") == 2
    err = capsys.readouterr().err
    assert "(config.stride: 2, now 3)" in err and len(err) < 300, err


def test_convert_paper_rule_and_ignore_free(tiny_root, tmp_path):
    out = tmp_path / "ds"
    assert _convert(tiny_root, out, "--label-rule", "paper", "--free-label", "ignore") == 0
    item = ShardDataset(out)[0]
    assert set(np.unique(item["labels"].numpy())) == {3, 4, 255}


def test_convert_errors_are_one_line(tiny_root, tmp_path, capsys):
    assert main(["kitti", "convert", "--root", str(tmp_path / "none"), "--sequences", "3",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no KITTI tracking data" in err
    (tiny_root / "training" / "calib" / "0001.txt").write_text(
        (FIXTURES / "calib_no_tr_velo_cam.txt").read_text())
    assert _convert(tiny_root, tmp_path / "o2") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "calibration has no Tr_velo_cam" in err
    # an output directory holding another dataset is refused
    other = tmp_path / "o3" / "train"
    other.mkdir(parents=True)
    (other / "shard-00000.h5").write_bytes(b"x")
    assert _convert(tiny_root, tmp_path / "o3") == 2
    assert "holds other shards" in capsys.readouterr().err


def test_every_scan_missing_is_an_error(tiny_root, tmp_path, capsys):
    for p in (tiny_root / "training" / "velodyne" / "0001").glob("*.bin"):
        p.unlink()
    assert _convert(tiny_root, tmp_path / "o") == 2
    err = capsys.readouterr().err
    # the first reason, with its file (it used to be only a count), and no folder left
    assert "no usable frame (6 skipped; the first: " in err and "000000.bin" in err
    assert "leave it out of --sequences" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_render_names_why_its_frame_was_skipped(tiny_root, tmp_path, capsys):
    scan = tiny_root / "training" / "velodyne" / "0001" / "000003.bin"
    scan.write_bytes(scan.read_bytes()[:1003])  # truncated
    assert main(["kitti", "render", "--root", str(tiny_root), "--sequence", "1", "--frame",
                 "3", "--out", str(tmp_path / "f.png")]) == 2
    err = capsys.readouterr().err
    assert "frame 3 was skipped: " in err and "000003.bin: 1003 bytes" in err
    assert "truncated" in err and err.count("\n") == 1
    # a later frame renders, and names the skipped scan of its filter history
    assert main(["kitti", "render", "--root", str(tiny_root), "--sequence", "1", "--frame",
                 "5", "--out", str(tmp_path / "g.png")]) == 0
    assert "warning: sequence 0001 frame 3: skipped: " in capsys.readouterr().out


@pytest.mark.parametrize("extra, message", [
    (["render", "--frame", "4", "--update-every", "0"], "--update-every must be >= 1, got 0"),
    (["render", "--frame", "4", "--update-every", "-2"], "--update-every must be >= 1, got -2"),
    (["convert", "--stride", "0"], "--stride must be >= 1, got 0"),
    (["convert", "--warmup", "-1"], "--warmup must be >= 0, got -1"),
    (["convert", "--update-every", "2"],
     "--stride 5 (the default: give --stride) is no multiple of --update-every 2"),
    (["convert", "--update-every", "2", "--stride", "4"],
     "--warmup 5 (the default: give --warmup) is no multiple of --update-every 2"),
])
def test_frame_counts_are_checked_by_their_flags(tiny_root, tmp_path, capsys, extra, message):
    """--update-every 0 was a ZeroDivisionError traceback, -2 named kitti.stride = -2000000."""
    cmd, *rest = extra
    where = (["--sequence", "1", "--out", str(tmp_path / "f.png")] if cmd == "render"
             else ["--sequences", "1", "--out", str(tmp_path / "o")])
    assert main(["kitti", cmd, "--root", str(tiny_root), *where, *rest]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not list(tmp_path.glob("[fo]*"))


def test_a_warmup_past_the_sequence_is_named_and_writes_nothing(tiny_root, tmp_path, capsys):
    assert main(["kitti", "convert", "--root", str(tiny_root), "--sequences", "1",
                 "--warmup", "45", "--out", str(tmp_path / "o")]) == 2
    assert "--warmup 45 is past its 6 frames" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_render_and_evaluate(tiny_root, tmp_path, capsys):
    png = tmp_path / "f.png"
    assert main(["kitti", "render", "--root", str(tiny_root), "--sequence", "1", "--frame", "3",
                 "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["kitti", "render", "--root", str(tiny_root), "--sequence", "1", "--frame", "3",
                 "--update-every", "2", "--out", str(png)]) == 2
    assert "pick a multiple of 2" in capsys.readouterr().err
    assert main(["kitti", "render", "--root", str(tiny_root), "--sequence", "1", "--frame", "-1",
                 "--out", str(png)]) == 2
    assert "--frame must be a frame number >= 0, got -1" in capsys.readouterr().err
    assert main(["kitti", "render", "--root", str(tiny_root), "--sequence", "1", "--frame", "9",
                 "--out", str(png)]) == 2
    assert "--frame 9: sequence 0001 has 6 frames (0 .. 5)" in capsys.readouterr().err
    assert main(["kitti", "render", "--root", str(tiny_root), "--sequence", "1", "--frame", "3",
                 "--out", str(tmp_path / "f.jpg")]) == 2
    assert "give a name ending in .png" in capsys.readouterr().err
    assert not (tmp_path / "f.jpg").exists()
    out = tmp_path / "ds"
    assert _convert(tiny_root, out) == 0
    capsys.readouterr()
    js = tmp_path / "m.json"
    assert main(["kitti", "evaluate", "--data", str(out), "--json", str(js)]) == 0
    text = capsys.readouterr().out  # an alias of dstenv benchmark --data: its report
    assert "| dst (default) |" in text and "3 frames" in text
    # without --out the report lives in a scratch folder that is removed: no "wrote" of it
    wrote = [ln for ln in text.splitlines() if ln.startswith("wrote ")]
    assert wrote == [f"wrote {js}"]
    assert "the report is not kept: add --out DIR" in text
    res = json.loads(js.read_text())["segmenters"]["dst (default)"]
    assert set(res) >= {"observed", "all", "visible"}
    # attack 17: a full disk cut the old --json file to a broken JSON (copied in place)
    import errno

    import dstenv.io

    before = js.read_bytes()

    real = dstenv.io.atomic_write_bytes

    def full(path, data, *a, **k):  # the disk fills at the --json file
        if str(path) == str(js):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data, *a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(dstenv.io, "atomic_write_bytes", full)
        assert main(["kitti", "evaluate", "--data", str(out), "--json", str(js)]) == 2
    err = capsys.readouterr().err
    assert f"--json {js}: cannot write it (No space left on device); the file there is " \
           "unchanged" in err
    assert js.read_bytes() == before


@pytest.mark.parametrize("osm", ["dangling.osm"])
def test_osm_with_dangling_refs(tiny_root, tmp_path, capsys, osm):
    pytest.importorskip("dstenv.sim.osm")
    rc = _convert(tiny_root, tmp_path / "o", "--osm", str(FIXTURES / osm))
    out, err = capsys.readouterr()
    if rc == 0:  # the loader drops the broken way: the map is used
        assert "map: " in out and "aligned by OXTS" in out
        item = ShardDataset(tmp_path / "o")[0]
        assert (item["labels"].numpy() != 255).any()
    else:  # or refuses it in one line naming the file
        assert rc == 2 and err.count("\n") == 1 and osm in err


def test_a_missing_sequence_in_the_list_writes_nothing(tiny_root, tmp_path, capsys):
    # every sequence is read before any shard is written: the good one of the list
    # would otherwise be left as a shard without a manifest
    out = tmp_path / "o"
    assert main(["kitti", "convert", "--root", str(tiny_root), "--sequences", "0001,0005",
                 "--stride", "2", "--warmup", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "0005: missing scan folder (sequences there: 0001)" in err
    assert not out.exists() or not list(out.rglob("*.h5*"))


def test_a_root_one_level_too_deep_says_where_to_point(tiny_root, tmp_path, capsys):
    deep = tiny_root / "training" / "velodyne"
    assert main(["kitti", "convert", "--root", str(deep), "--sequences", "0001",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "at KITTI's training/ folder or the one above it" in err


def test_a_convert_that_dies_leaves_a_folder_readers_refuse(tiny_root, tmp_path, capsys):
    from .conftest import make_sequence

    make_sequence(tiny_root.parent / "k2", seq="0002")
    for name in ("velodyne/0002", "calib/0002.txt", "oxts/0002.txt", "label_02/0002.txt"):
        src = tiny_root.parent / "k2" / "training" / name
        src.rename(tiny_root / "training" / name)
    for scan in (tiny_root / "training" / "velodyne" / "0002").glob("*.bin"):
        scan.write_bytes(b"")  # every scan of the second sequence is unusable
    out = tmp_path / "o"
    assert _convert(tiny_root, out) == 0  # 0001 alone: complete, with a manifest
    assert main(["kitti", "convert", "--root", str(tiny_root), "--sequences", "0001,0002",
                 "--stride", "2", "--warmup", "0", "--out", str(out)]) == 2
    assert "sequence 0002: no usable frame" in capsys.readouterr().err
    # the old manifest went first: 0001's shard alone is not taken for the dataset
    assert not (out / "manifest.json").exists()
    with pytest.raises(ValueError, match="no manifest.json, but its shards come from dstenv "
                                         "kitti convert.*rerun its command"):
        ShardDataset(out)
    assert main(["kitti", "evaluate", "--data", str(out)]) == 2
    assert "did not finish" in capsys.readouterr().err
    assert _convert(tiny_root, out) == 0 and len(ShardDataset(out)) > 0  # rerun: complete


def test_convert_warns_of_scans_without_a_pose_and_refuses_a_held_folder(tiny_root, tmp_path,
                                                                         capsys):
    from dstenv.data.lock import dataset_lock

    oxts = tiny_root / "training" / "oxts" / "0001.txt"
    rows = oxts.read_text().splitlines()
    labels = tiny_root / "training" / "label_02" / "0001.txt"
    labels.write_text("\n".join(r for r in labels.read_text().splitlines()
                                if int(r.split()[0]) < 5) + "\n")
    oxts.write_text("\n".join(rows[:5]) + "\n")
    out = tmp_path / "o"
    assert _convert(tiny_root, out) == 0
    said = capsys.readouterr().out
    assert "warning: sequence 0001: 1 scans past the OXTS file's 5 rows have no pose" in said
    with dataset_lock(out):  # another live writer
        assert _convert(tiny_root, out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "another run writes into it" in err


def test_benchmark_refuses_the_drives_of_another_kitti_run(tiny_root, tmp_path, capsys):
    from dstenv.config import CLIError
    from dstenv.segment.real import convert_sequences

    data = tmp_path / "run" / "kitti" / "data"
    convert_sequences(str(tiny_root), ["0001"], None, data)
    convert_sequences(str(tiny_root) + "/", ["1"], None, data)  # the same drives: resumes
    other = tmp_path / "elsewhere"
    tiny_root.rename(other)
    with pytest.raises(CLIError, match=r"holds the drives of another --kitti run \(.*kitti "
                                       r"sequences 0001, map none\); use another --out"):
        convert_sequences(str(other), ["0001"], None, data)
    # a sequence the root lacks is named before the simulated benchmark runs
    assert main(["benchmark", "--preset", "smoke", "--kitti", str(other), "--sequences",
                 "0002", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "0002: missing scan folder" in err
    assert not (tmp_path / "b").exists()


def test_render_into_a_folder_is_refused_before_converting(tiny_root, tmp_path, capsys):
    (tmp_path / "pic.png").mkdir()
    assert main(["kitti", "render", "--root", str(tiny_root), "--sequence", "1", "--frame", "3",
                 "--out", str(tmp_path / "pic.png")]) == 2
    err = capsys.readouterr()
    assert "pic.png: is a directory" in err.err and "sequence 0001" not in err.out
