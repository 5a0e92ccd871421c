"""Generation with a stand-in pipeline: determinism, resume, atomicity, splits, errors."""

from __future__ import annotations

import hashlib

import pytest

from dstenv.data import generate as gen
from dstenv.data.manifest import ManifestError, load_manifest
from dstenv.data.sampling import split_of_seed
from dstenv.data.shards import ShardReader, partial_path

CONFIG = {"grid": {"height": 8, "width": 6, "cell_size": 0.5}}


@pytest.fixture(autouse=True)
def _use_fake(fake_pipeline):
    return fake_pipeline


def _spec(**kw):
    base = dict(config=CONFIG, frames=20, seed=5, frames_per_shard=4, episode_length=7,
                stride=3, warmup=1)
    base.update(kw)
    return gen.GenerateSpec(**base)


def _digests(root):
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def test_plan_auto_splits():
    tasks = gen.plan(_spec())
    assert [(t.file, t.frames) for t in tasks] == [
        ("train/shard-00000.h5", 4), ("train/shard-00001.h5", 4), ("train/shard-00002.h5", 4),
        ("train/shard-00003.h5", 4), ("val/shard-00000.h5", 2), ("test/shard-00000.h5", 2)]
    assert gen.split_frames(3, "auto") == {"train": 3}
    assert gen.split_frames(9, "test") == {"test": 9}
    # multiples of 10 split 80/10/10; one more frame adds one to one split, never takes
    # one from train (rounding gave 105 -> train 85, 106 -> train 84: growth refused)
    assert gen.split_frames(2500, "auto") == {"train": 2000, "val": 250, "test": 250}
    assert gen.split_frames(106, "auto") == {"train": 86, "val": 10, "test": 10}
    prev: dict[str, int] = {}
    for n in range(1, 300):
        now = gen.split_frames(n, "auto")
        assert sum(now.values()) == n and all(now.get(k, 0) >= v for k, v in prev.items())
        prev = now


def test_generate_is_deterministic_and_splits_are_disjoint(tmp_path):
    m1 = gen.generate(_spec(), tmp_path / "a", progress=False)
    m2 = gen.generate(_spec(), tmp_path / "b", progress=False)
    assert _digests(tmp_path / "a") == _digests(tmp_path / "b")
    assert m1 == m2 and m1["frames"] == 20
    assert {k: v["frames"] for k, v in m1["splits"].items()} == {"train": 16, "val": 2, "test": 2}
    seen = {}
    for e in m1["shards"]:
        with ShardReader(tmp_path / "a" / e["file"]) as r:
            seeds = {int(r[i].seed) for i in range(len(r))}
            steps = [int(r[i].step) for i in range(len(r))]
            assert set(steps) <= {1, 4}  # warmup 1, stride 3, length 7
            assert r.attrs["task"]["split"] == e["split"] == r.attrs["split"]
        assert all(split_of_seed(s) == e["split"] for s in seeds)
        seen.setdefault(e["split"], set()).update(seeds)
    assert not (seen["train"] & seen["test"]) and not (seen["train"] & seen["val"])
    assert gen.generate(_spec(seed=6), tmp_path / "c", progress=False) != m1


def test_resume_skips_finished_shards_and_crash_leaves_no_shard(tmp_path, monkeypatch,
                                                                fake_pipeline):
    fake = fake_pipeline
    out = tmp_path / "d"
    calls = {"n": 0}
    real_add = gen.ShardWriter.add

    def crashing_add(self, frame):
        calls["n"] += 1
        if calls["n"] == 11:  # third shard, third frame
            raise OSError(28, "No space left on device")
        real_add(self, frame)

    monkeypatch.setattr(gen.ShardWriter, "add", crashing_add)
    with pytest.raises(gen.GenerateError, match="No space left on device; 2 finished shards "
                                                "kept .* rerun the same command to resume"):
        gen.generate(_spec(), out, progress=False)
    assert sorted(p.name for p in (out / "train").iterdir()) == ["shard-00000.h5",
                                                                 "shard-00001.h5"]
    assert not (out / "manifest.json").exists()
    # a hard kill leaves a .partial file: the rerun overwrites it
    partial_path(out / "train" / "shard-00002.h5").write_bytes(b"half")
    monkeypatch.setattr(gen.ShardWriter, "add", real_add)
    before = _digests(out)
    fake.resets.clear()
    m = gen.generate(_spec(), out, progress=False)
    assert all(_digests(out)[k] == v for k, v in before.items() if k.endswith(".h5"))
    assert not list(out.rglob("*.partial"))
    assert len(fake.resets) == 2 * 2 + 1 + 1  # 2 train shards of 2 episodes, val, test
    gen.generate(_spec(), tmp_path / "ref", progress=False)
    assert _digests(out) == _digests(tmp_path / "ref")
    assert load_manifest(out, verify="hash") == m


def test_resume_refuses_other_settings(tmp_path, fake_pipeline):
    fake = fake_pipeline
    gen.generate(_spec(frames=8, split="train"), tmp_path, progress=False)
    with pytest.raises(gen.GenerateError, match=r"shard-00000\.h5 was made with other settings "
                                                r"\(--stride: 3, now 2\)"):
        gen.generate(_spec(frames=8, split="train", stride=2), tmp_path, progress=False)
    # spelled as on the command line: --compression none, not None
    with pytest.raises(gen.GenerateError, match=r"\(--compression: gzip, now none\)"):
        gen.generate(_spec(frames=8, split="train", compression=None), tmp_path, progress=False)
    with pytest.raises(gen.GenerateError, match=r"\(--float32: off, now on\)"):
        gen.generate(_spec(frames=8, split="train", quantize=False), tmp_path, progress=False)
    with pytest.raises(gen.GenerateError, match=r"\(--gzip-level: 1, now 5\)"):
        gen.generate(_spec(frames=8, split="train", compression_level=5), tmp_path,
                     progress=False)
    with pytest.raises(gen.GenerateError, match="another configuration"):
        gen.generate(_spec(frames=8, split="train", config={"grid": {"height": 4, "width": 4,
                                                                     "cell_size": 0.5}}),
                     tmp_path, progress=False)
    with pytest.raises(gen.GenerateError, match=r"not part of this run \(train/shard-00001"
                                                r"\.h5\.\.\.; a run of more --frames made it: "
                                                r"this one makes 4"):
        gen.generate(_spec(frames=4, split="train"), tmp_path, progress=False)
    # another --split: the refusal names it
    with pytest.raises(gen.GenerateError, match=r"a train shard, this run writes val only "
                                                r"\(--split\)"):
        gen.generate(_spec(frames=8, split="val"), tmp_path, progress=False)
    # growing the dataset keeps the finished shards and regenerates only the short one
    fake.resets.clear()
    m = gen.generate(_spec(frames=10, split="train"), tmp_path, progress=False)
    assert m["frames"] == 10 and len(fake.resets) == 1
    # shrinking it within its last shard would drop frames: refused, nothing touched
    last = tmp_path / "train" / "shard-00002.h5"
    before = last.read_bytes()
    with pytest.raises(gen.GenerateError, match=r"shard-00002\.h5 holds 2 frames, this run "
                                                r"makes 1 there: it would drop frames"):
        gen.generate(_spec(frames=9, split="train"), tmp_path, progress=False)
    assert last.read_bytes() == before


def test_a_foreign_manifest_is_never_replaced(tmp_path, fake_pipeline):
    for text in ("x", '{"format": "other"}'):
        (tmp_path / "manifest.json").write_text(text)
        with pytest.raises(gen.GenerateError, match="not a dstenv manifest, and this run would "
                                                    "replace it; use another --out"):
            gen.generate(_spec(frames=4, split="train"), tmp_path, progress=False)
        assert (tmp_path / "manifest.json").read_text() == text
        assert not list(tmp_path.rglob("*.h5*"))
    # a dstenv manifest of this run's own shards is rewritten as before
    (tmp_path / "manifest.json").unlink()
    gen.generate(_spec(frames=4, split="train"), tmp_path, progress=False)
    gen.generate(_spec(frames=4, split="train"), tmp_path, progress=False)


def test_unwritable_output_is_one_line(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(gen.GenerateError, match=r"output directory .*file/out is not writable"):
        gen.generate(_spec(), blocker / "out", progress=False)
    with pytest.raises(gen.GenerateError, match=r"output directory .*file is a file; give a"):
        gen.generate(_spec(), blocker, progress=False)


def test_manifest_mismatch_is_reported(tmp_path):
    gen.generate(_spec(frames=8, split="val"), tmp_path, progress=False)
    shard = tmp_path / "val" / "shard-00001.h5"
    shard.write_bytes(shard.read_bytes() + b"\0")
    with pytest.raises(ManifestError, match=r"manifest\.json: val/shard-00001\.h5 is \d+ bytes "
                                            r"on disk, the manifest says \d+"):
        load_manifest(tmp_path)
    shard.unlink()
    with pytest.raises(ManifestError, match="lists val/shard-00001.h5 but that file is missing"):
        load_manifest(tmp_path)
    (tmp_path / "val" / "extra.h5").write_bytes(b"")
    (tmp_path / "manifest.json").write_text("{")
    with pytest.raises(ManifestError, match="unreadable manifest"):
        load_manifest(tmp_path)


@pytest.mark.parametrize("edit, message", [
    (lambda m: m["shards"][0].pop("bytes"), r"shard entry 0 \(val/shard-00000\.h5\): 'bytes' is "
                                            "missing or not an integer"),
    (lambda m: m["shards"][1].update(sha256=None), r"'sha256' is missing"),
    (lambda m: m["shards"][0].update(frames="8"), r"'frames' is missing or not an integer"),
    (lambda m: m.update(shards=5), r"'shards' must be a non-empty list"),
    (lambda m: m.update(shards=None), r"'shards' must be a non-empty list"),
    (lambda m: m["shards"][0].update(grid_shape="abc"), r"'grid_shape' is missing"),
    (lambda m: m["shards"][0].update(cell_size=None), r"'cell_size' is missing or not a number"),
    (lambda m: m.update(frames=999), r"'frames' is 999 but its shard entries add up to 8"),
    (lambda m: m.update(cell_size=float("nan")), r"'cell_size' is nan but its shard entries "
                                                 r"say 0\.5"),
    (lambda m: m.pop("splits"), r"'splits' is None but"),
    # the shares printed by dstenv info are checked against the counts, leaf by leaf
    (lambda m: m["class_frequencies"].update(moving=0.9),
     r"'class_frequencies.moving' is 0.9 but its shard entries add up to 0\."),
    (lambda m: m["class_frequencies"].update(moving="abc"), r"'class_frequencies.moving' is "
                                                            r"'abc'"),
    (lambda m: m.pop("class_frequencies"), r"'class_frequencies' is None"),
    (lambda m: m["splits"]["val"]["class_counts"].__setitem__(0, 1),
     r"'splits.val.class_counts' is \[1, "),
    (lambda m: m["shards"].append(dict(m["shards"][0])), r"val/shard-00000\.h5 is listed twice"),
    # attack 17: another spelling of the same file was read twice
    (lambda m: m["shards"].append(dict(m["shards"][0], file="val/./shard-00000.h5")),
     r"val/\./shard-00000\.h5 is listed twice"),
    (lambda m: m["shards"].append(dict(m["shards"][0], file="train/../val/shard-00000.h5")),
     r"is listed twice"),
])
def test_an_edited_manifest_is_one_line(tmp_path, edit, message):
    import json

    gen.generate(_spec(frames=8, split="val"), tmp_path, progress=False)
    path = tmp_path / "manifest.json"
    m = json.loads(path.read_text())
    edit(m)
    path.write_text(json.dumps(m))
    with pytest.raises(ManifestError, match=message) as info:
        load_manifest(tmp_path)
    assert "delete it and rerun the command" in str(info.value)
    assert "\n" not in str(info.value)


def test_manifest_counts_are_checked_against_the_shards(tmp_path):
    """Counts edited consistently (entry, total, split) agree with each other but not with
    the shard's own; a key named twice is refused, not read as its last value."""
    import json

    gen.generate(_spec(frames=8, split="val"), tmp_path, progress=False)
    path = tmp_path / "manifest.json"
    text = path.read_text()
    m = json.loads(text)
    for counts in (m["shards"][0]["class_counts"], m["class_counts"],
                   m["splits"]["val"]["class_counts"]):
        counts[0] += 1000
    n = sum(m["class_counts"])
    m["class_frequencies"] = {k: c / n for k, c in zip(m["classes"], m["class_counts"])}
    path.write_text(json.dumps(m))
    load_manifest(tmp_path, verify="size")  # consistent with itself
    with pytest.raises(ManifestError, match=r"val/shard-00000\.h5 holds class counts \[\d+"):
        load_manifest(tmp_path)
    path.write_text(text.replace('"frames": 8,', '"frames": 99, "frames": 8,', 1))
    with pytest.raises(ManifestError, match="key 'frames' appears twice in one object"):
        load_manifest(tmp_path)


def _flip_a_data_byte(path):
    """Corrupt one byte inside a compressed chunk of ``labels`` (the size stays)."""
    import h5py

    with h5py.File(path, "r") as f:
        offset = f["labels"].id.get_chunk_info(0).byte_offset
    raw = bytearray(path.read_bytes())
    raw[offset + 5] ^= 0xFF
    path.write_bytes(bytes(raw))


def test_resume_regenerates_a_shard_with_a_corrupt_chunk(tmp_path, capsys):
    spec = _spec()
    gen.generate(spec, tmp_path, progress=False)
    good = _digests(tmp_path)
    shard = tmp_path / "train" / "shard-00001.h5"
    _flip_a_data_byte(shard)
    (tmp_path / "manifest.json").unlink()  # as after a kill before the manifest
    gen.generate(spec, tmp_path, progress=False)
    assert "kept as shard-00001.h5.corrupt" in capsys.readouterr().err
    again = {k: v for k, v in _digests(tmp_path).items() if not k.endswith(".corrupt")}
    assert again == good  # same bytes as the first run, manifest hash included


def test_info_verify_frames_reads_every_chunk(tmp_path, capsys):
    from dstenv.cli import main

    gen.generate(_spec(), tmp_path, progress=False)
    _flip_a_data_byte(tmp_path / "train" / "shard-00001.h5")
    assert main(["info", str(tmp_path)]) == 0  # attrs: sizes, frames and settings only
    capsys.readouterr()
    assert main(["info", str(tmp_path), "--verify", "frames"]) == 2
    assert "shard-00001.h5" in capsys.readouterr().err
    (tmp_path / "manifest.json").unlink()  # without one, frames and hash read every chunk
    for level in ("frames", "hash"):
        assert main(["info", str(tmp_path), "--verify", level]) == 2
        assert "shard-00001.h5" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "train" / "shard-00000.h5"), "--verify", "hash"]) == 0
    assert "every chunk read" in capsys.readouterr().out


def test_a_same_size_shard_of_another_seed_is_caught_by_default(tmp_path):
    gen.generate(_spec(), tmp_path / "a", progress=False)
    gen.generate(_spec(seed=6), tmp_path / "b", progress=False)
    a, b = tmp_path / "a" / "val" / "shard-00000.h5", tmp_path / "b" / "val" / "shard-00000.h5"
    if a.stat().st_size != b.stat().st_size:  # make sizes equal: the old check's blind spot
        pytest.skip("the two shards differ in size here; the size check alone catches it")
    a.write_bytes(b.read_bytes())
    load_manifest(tmp_path / "a", verify="size")  # sizes agree: the old default passed
    with pytest.raises(ManifestError, match="made with other settings or seeds"):
        load_manifest(tmp_path / "a")


def test_manifest_paths_stay_inside_the_dataset(tmp_path):
    import json

    gen.generate(_spec(), tmp_path / "d", progress=False)
    m = json.loads((tmp_path / "d" / "manifest.json").read_text())
    m["shards"][0]["file"] = "../../etc/passwd"
    (tmp_path / "d" / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(ManifestError, match="points outside"):
        load_manifest(tmp_path / "d", verify="size")


def test_generate_refuses_lzf_with_the_reason():
    with pytest.raises(ValueError, match="lzf .*does not write the same bytes twice"):
        _spec(compression="lzf")



def test_generate_refuses_before_simulating_what_would_fail_in_a_shard(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="frame.labels = false: generate stores every"):
        _spec(config={**CONFIG, "frame": {"labels": False}})
    # a map pool would put the same maps in every split (test maps in training)
    with pytest.raises(ValueError, match="world.map.pool = 3: generate draws a map per"):
        _spec(config={**CONFIG, "world": {"map": {"pool": 3}}})
    monkeypatch.chdir(tmp_path)
    osm = {**CONFIG, "world": {"map": {"kind": "osm", "osm_file": "town.osm"}}}
    with pytest.raises(ValueError, match=r"world\.map\.osm_file 'town\.osm': no such file"):
        _spec(config=osm)
    (tmp_path / "town.osm").write_text("<osm/>")
    assert _spec(config=osm).frames == 20  # found in the current folder


def test_a_shard_changed_since_its_manifest_is_made_again(tmp_path, fake_pipeline, capsys):
    """A flip that every chunk checksum misses (e.g. in HDF5's own index) still changes
    the file's hash: a rerun sets it aside instead of listing its corrupt bytes."""
    m = gen.generate(_spec(frames=8, split="train"), tmp_path, progress=False)
    shard = tmp_path / "train" / "shard-00001.h5"
    good = shard.read_bytes()
    with open(shard, "ab") as fh:  # bytes HDF5 never reads: only the hash sees them
        fh.write(b"\0")
    again = gen.generate(_spec(frames=8, split="train"), tmp_path, progress=False)
    assert "its bytes changed since the manifest listed them" in capsys.readouterr().err
    assert (tmp_path / "train" / "shard-00001.h5.corrupt").exists()
    assert shard.read_bytes() == good and again["shards"] == m["shards"]
    # shards of another --frames-per-shard are named by that setting
    with pytest.raises(gen.GenerateError, match=r"shard-00000\.h5 was made with other "
                                                r"settings \(--frames-per-shard: 4, now 3\)"):
        gen.generate(_spec(frames=8, split="train", frames_per_shard=3), tmp_path,
                     progress=False)
    with pytest.raises(gen.GenerateError, match=r"not part of this run \(train/shard-00001"
                                                r"\.h5\.\.\.; made with --frames-per-shard: 4, "
                                                r"now 8\)"):
        gen.generate(_spec(frames=8, split="train", frames_per_shard=8), tmp_path,
                     progress=False)
    # another configuration is refused, naming the setting
    with pytest.raises(gen.GenerateError, match=r"another configuration \(--grid \(height\): "):
        gen.generate(_spec(frames=8, split="train", config={"grid": {"height": 4, "width": 4,
                                                                     "cell_size": 0.5}}),
                     tmp_path, progress=False)


@pytest.mark.parametrize("scenario, over", [("osm", {}), (None, {"source": "highway"})])
def test_map_reuse_on_a_fixed_map_is_refused_before_any_folder(tmp_path, capsys, scenario, over):
    from dstenv.cli import main

    argv = ["generate", "--frames", "4", "--grid", "32", "--episodes-per-map", "2", "--quiet",
            "--out", str(tmp_path / "d")]
    argv += ["--scenario", scenario] if scenario else []
    argv += [f"--set=source={over['source']}"] if over else []
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--episodes-per-map) needs source 'city' with a procedural map" in err, err
    assert "give 1" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists()  # refused before any folder or map is made


def test_a_masses_clash_names_the_flag(tmp_path):
    framed = {**CONFIG, "frame": {"masses": False}}  # as every full configuration has
    gen.generate(_spec(frames=4, split="train", config=framed), tmp_path, progress=False)
    with pytest.raises(gen.GenerateError, match=r"another configuration \(--masses: off, now on"):
        gen.generate(_spec(frames=4, split="train", config=framed, masses=True), tmp_path,
                     progress=False)


@pytest.mark.parametrize("extra", [["--gzip-level", "5"], ["--deflate", "zlib"]])
def test_gzip_settings_with_compression_none_are_refused(tmp_path, capsys, extra):
    from dstenv.cli import main

    argv = ["generate", "--frames", "2", "--grid", "32", "--quiet", "--compression", "none",
            "--out", str(tmp_path / "d"), *extra]
    assert main(argv) == 2
    assert "with --compression none they would do nothing" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_a_folder_of_several_datasets_is_not_read_as_one(tmp_path, capsys):
    from dstenv.cli import main
    from dstenv.data.datasets import ShardDataset

    gen.generate(_spec(frames=4, split="train"), tmp_path / "a", progress=False)
    gen.generate(_spec(frames=4, split="train", seed=6), tmp_path / "b", progress=False)
    with pytest.raises(ValueError, match=r"no manifest\.json of its own; it holds 2 "
                                         r"dataset\(s\) \(a, b\): give one of them"):
        ShardDataset(tmp_path, split="train")
    assert main(["info", str(tmp_path)]) == 2
    assert "it holds 2 dataset(s) (a, b)" in capsys.readouterr().err
    assert len(ShardDataset(tmp_path / "a", split="train")) == 4  # each one still reads


def test_a_dataset_inside_a_dataset_or_its_split_folder_is_named_as_such(tmp_path, capsys):
    import shutil

    from dstenv.cli import main
    from dstenv.data.datasets import ShardDataset

    gen.generate(_spec(frames=4, split="train"), tmp_path / "a", progress=False)
    gen.generate(_spec(frames=4, split="train", seed=6), tmp_path / "b", progress=False)
    # b copied inside a: not "changed files" to delete, but a dataset to move out
    shutil.copytree(tmp_path / "b", tmp_path / "a" / "inner")
    with pytest.raises(ValueError, match=r"holds another dataset, inner \(its own "
                                         r"manifest\.json\): move it out of"):
        ShardDataset(tmp_path / "a", split="train")
    shutil.rmtree(tmp_path / "a" / "inner")
    # the split folder of a finished dataset: not an unfinished run
    with pytest.raises(ValueError, match=r"a/train is the train split of the dataset .*a: give"):
        ShardDataset(tmp_path / "a" / "train", split="train")
    # a folder of shards without a manifest: info says what that means
    shutil.copytree(tmp_path / "b" / "train", tmp_path / "c" / "train")
    assert main(["info", str(tmp_path / "c")]) == 0
    assert "has no manifest.json: if a dstenv run made it, that run did not finish" in \
        capsys.readouterr().err


def test_benchmark_on_a_folder_of_datasets_writes_nothing(tmp_path, capsys):
    from dstenv.cli import main

    gen.generate(_spec(frames=4, split="train"), tmp_path / "d" / "a", progress=False)
    gen.generate(_spec(frames=4, split="train", seed=6), tmp_path / "d" / "b", progress=False)
    assert main(["benchmark", "--data", str(tmp_path / "d"), "--out", str(tmp_path / "bm"),
                 "--quiet"]) == 2
    assert "it holds 2 dataset(s) (a, b)" in capsys.readouterr().err
    assert not (tmp_path / "bm" / "data-identity.json").exists()


def test_a_rerun_says_what_is_there_already(tmp_path, fake_pipeline, capsys):
    """A rerun of a finished run says that nothing was generated; a resumed one how much
    was kept (a progress bar starting at 100 % alone looked like work done again)."""
    spec = _spec(frames=8, split="train")
    gen.generate(spec, tmp_path, progress=True)
    assert "there already" not in capsys.readouterr().err
    gen.generate(spec, tmp_path, progress=True)
    err = capsys.readouterr().err
    assert "all 8 frames are there already" in err and "nothing to generate" in err
    assert "generate:" not in err.replace("dstenv generate:", "")  # no bar
    (tmp_path / "train" / "shard-00001.h5").unlink()
    gen.generate(spec, tmp_path, progress=True)
    assert "resuming: 1 of 2 shard(s), 4 of 8 frames" in capsys.readouterr().err
    gen.generate(spec, tmp_path, progress=False)
    assert capsys.readouterr().err == ""


def test_fewer_frames_with_split_auto_are_not_blamed_on_split(tmp_path, fake_pipeline):
    """Attack 15: 8 frames into a 12-frame --split auto dataset deal no frame to test, and
    the refusal said 'this run writes train, val only (--split)', though --split was the
    same."""
    gen.generate(_spec(frames=12, split="auto"), tmp_path, progress=False)
    with pytest.raises(gen.GenerateError, match=r"a run of more --frames made it: this one "
                                                r"makes 8") as err:
        gen.generate(_spec(frames=8, split="auto"), tmp_path, progress=False)
    assert "--split" not in str(err.value)


def test_generate_into_a_kitti_conversion_names_the_tool(tmp_path, fake_pipeline):
    """Attack 15: it said 'made with --compression: none, now gzip'."""
    from dstenv.data.manifest import write_manifest

    gen.generate(_spec(frames=4, split="train"), tmp_path, progress=False)
    write_manifest(tmp_path, meta={"command": "kitti convert"})  # the same shards, re-listed
    with pytest.raises(gen.GenerateError, match=r"holds a dataset of dstenv kitti convert, "
                                                r"not of generate; use another --out"):
        gen.generate(_spec(frames=4, split="train"), tmp_path, progress=False)


@pytest.mark.parametrize("address, message", [
    ("127.0.0.1:1", r"--ray 127\.0\.0\.1:1: no Ray head answers at 127\.0\.0\.1:1 \("),
    ("ray://127.0.0.1:1", r"no Ray head answers at 127\.0\.0\.1:1"),
    ("127.0.0.1:99999", r"expected HOST:PORT of a head started with 'ray start --head'"),
    ("garbage", r"expected HOST:PORT"),
])
def test_a_ray_address_where_no_head_answers_fails_at_once(tmp_path, address, message,
                                                           monkeypatch):
    """Attack 16: ray.init waited minutes on it (ignoring SIGTERM), naming another address."""
    monkeypatch.setattr("dstenv.data.ray_backend.ray_installed", lambda: True)
    with pytest.raises(gen.GenerateError, match=message):
        gen.generate(_spec(frames=4, split="train"), tmp_path / "o", ray_address=address,
                     progress=False)
    assert not (tmp_path / "o").exists()  # refused before the folder


@pytest.mark.parametrize("address", ["local", "127.0.0.1:6379"])
def test_ray_not_installed_is_named_before_the_folder(tmp_path, address, monkeypatch):
    """Newcomer 7: a progress bar and an empty folder came first."""
    monkeypatch.setattr("dstenv.data.ray_backend.ray_installed", lambda: False)
    with pytest.raises(gen.GenerateError, match=r"--ray needs Ray: pip install -e '\.\[ray\]'"):
        gen.generate(_spec(frames=4, split="train"), tmp_path / "o", ray_address=address,
                     progress=False)
    assert not (tmp_path / "o").exists()


def test_a_split_edited_in_the_manifest_is_refused(tmp_path):
    """Attack 17: an entry moved to another split by hand (totals made consistent) put its
    frames in no split of ShardDataset and in another in dstenv info."""
    import json

    from dstenv.data.manifest import build_manifest

    gen.generate(_spec(frames=8, split="val"), tmp_path, progress=False)
    path = tmp_path / "manifest.json"
    m = json.loads(path.read_text())
    m["shards"][0]["split"] = "test"
    m.update({k: v for k, v in build_manifest(m["shards"]).items() if k != "shards"})
    path.write_text(json.dumps(m))
    load_manifest(tmp_path, verify="size")  # consistent with itself
    with pytest.raises(ManifestError, match=r"val/shard-00000\.h5 is a shard of split 'val', "
                                            r"the manifest says 'test' \(the manifest was edited"):
        load_manifest(tmp_path)


def test_a_manifest_number_python_cannot_read_names_the_file(tmp_path):
    """Attack 17: an integer of 5000 digits gave Python's message without the file."""
    import sys

    if not hasattr(sys, "get_int_max_str_digits"):
        pytest.skip("this Python reads integers of any length")
    gen.generate(_spec(frames=8, split="val"), tmp_path, progress=False)
    path = tmp_path / "manifest.json"
    path.write_text(path.read_text().replace('"frames": 8', '"frames": ' + "9" * 5000, 1))
    with pytest.raises(ManifestError, match=r"manifest\.json: unreadable manifest: Exceeds the "
                                            r"limit \(4300 digits\)"):
        load_manifest(tmp_path)
