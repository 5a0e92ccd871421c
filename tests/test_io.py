"""The one atomic writer: all or nothing, named errors, readable permissions."""

from __future__ import annotations

import errno
import os
import stat

import pytest

from dstenv.io import atomic_path, atomic_write_text, partial_path


def test_write_replaces_whole_and_leaves_no_partial(tmp_path):
    target = tmp_path / "sub" / "a.json"
    atomic_write_text(target, "one")
    atomic_write_text(target, "two")
    assert target.read_text() == "two"
    assert sorted(p.name for p in target.parent.iterdir()) == ["a.json"]
    # created with the umask like any file (a PNG for a user, not 0600)
    mode = stat.S_IMODE(target.stat().st_mode)
    assert mode == 0o666 & ~_umask()


def test_error_keeps_the_old_file_and_names_it(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(OSError) as info:
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert info.value.filename == str(target) and info.value.errno == errno.ENOSPC
    assert target.read_text() == "old" and not partial_path(target).exists()


def test_other_errors_clean_up_too(tmp_path):
    with pytest.raises(KeyError):
        with atomic_path(tmp_path / "b.txt") as tmp:
            tmp.write_text("x")
            raise KeyError("boom")
    assert list(tmp_path.iterdir()) == []


def _umask() -> int:
    old = os.umask(0)
    os.umask(old)
    return old


def test_output_file_never_replaces_a_datasets_file_or_a_binary(tmp_path):
    import pytest

    from dstenv.io import output_file

    ds = tmp_path / "ds"
    (ds / "test").mkdir(parents=True)
    (ds / "test" / "shard-00000.h5").write_bytes(b"\x89HDF\r\n\x1a\n\0\0")
    (ds / "manifest.json").write_text('{"format": "dstenv-manifest"}')
    for target in (ds / "manifest.json", ds / "test" / "shard-00000.h5", ds / "r.json"):
        with pytest.raises(ValueError, match="inside the dataset folder"):
            output_file(target, "--json")
    (tmp_path / "victim.h5").write_bytes(b"\x89HDF\r\n\x1a\n\0\0")
    with pytest.raises(ValueError, match=r"exists and is not a report \(JSON or CSV\)"):
        output_file(tmp_path / "victim.h5", "--json")
    (tmp_path / "old.json").write_text("{}")
    assert output_file(tmp_path / "old.json", "--json") == tmp_path / "old.json"  # a report
    (tmp_path / "runs.csv").write_text("a,b\n1,2\n")
    assert output_file(tmp_path / "runs.csv", "--csv") == tmp_path / "runs.csv"
    (tmp_path / "runs.txt").write_text("policy,success\na,1\n")  # a CSV by its header
    assert output_file(tmp_path / "runs.txt", "--csv") == tmp_path / "runs.txt"
    (tmp_path / "tool.py").write_text("import os, sys\n")  # a comma, but code
    with pytest.raises(ValueError, match="exists and is not a report"):
        output_file(tmp_path / "tool.py", "--json")
    # attack 16: any text file was replaced (a script, a README), and as root a device,
    # a pipe or a link became a plain file (/dev/null did)
    for name in ("script.py", "README.md", "my.toml"):
        (tmp_path / name).write_text("print('mine')\n")
        with pytest.raises(ValueError, match="exists and is not a report"):
            output_file(tmp_path / name, "--json")
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "link.json").symlink_to(tmp_path / "old.json")
    for target in (tmp_path / "fifo", tmp_path / "link.json", "/dev/null"):
        with pytest.raises(ValueError, match="exists and is not a regular file"):
            output_file(target, "--json")
    from dstenv.io import png_path

    (tmp_path / "notes.png").write_text("not a picture")
    with pytest.raises(ValueError, match="exists and is not a PNG picture"):
        png_path(tmp_path / "notes.png")


def test_png_path_under_a_file_is_named(tmp_path):
    from dstenv.io import png_path

    (tmp_path / "r1.png").write_bytes(b"x")
    with pytest.raises(ValueError, match=r"--out .*r1\.png/x\.png: cannot create its folder "
                                         r"\(.*r1\.png is a file\)"):
        png_path(tmp_path / "r1.png" / "x.png")
    assert png_path(tmp_path / "new" / "x.png") == tmp_path / "new" / "x.png"


def test_output_file_probes_a_folder_access_calls_writable(tmp_path):
    """Root's access() says yes in /proc (or on a read-only mount); the results of a
    long benchmark were then lost at the end. A probe file finds it first, and is gone."""
    from dstenv.io import output_file

    real = os.open

    def no_create(path, flags, *a, **k):  # a folder that refuses new files
        if flags & os.O_CREAT and str(path).startswith(str(tmp_path)):
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real(path, flags, *a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(os, "open", no_create)
        with pytest.raises(ValueError, match=r"--json .*r\.json: cannot create a file in .* "
                                             r"\(Read-only file system\); give a path"):
            output_file(tmp_path / "r.json", "--json")
    assert output_file(tmp_path / "r.json", "--json") == tmp_path / "r.json"
    assert list(tmp_path.iterdir()) == []  # the probe is removed
    if os.path.isdir("/proc/self") and os.geteuid() == 0:
        with pytest.raises(ValueError, match=r"/proc is not writable \(dr-xr-xr-x\)"):
            output_file("/proc/x.json", "--json")


def test_a_folder_marked_read_only_is_refused_even_to_root(tmp_path):
    """Newcomer 7: as root, kitti convert wrote beside --root into a shared data folder
    of mode r-x (root's writes ignore the mode)."""
    from dstenv.io import output_file, output_folder

    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o555)
    try:
        with pytest.raises(ValueError, match=r"--out .*shared/out: .*shared is not writable "
                                             r"\(dr-xr-xr-x\); give a path you can write to"):
            output_folder(shared / "out", "--out")
        with pytest.raises(ValueError, match=r"shared is not writable"):
            output_file(shared / "deep" / "r.json", "--json")
        assert list(shared.iterdir()) == []
    finally:
        shared.chmod(0o755)


def test_output_folder_keeps_outputs_apart_from_datasets_inputs_and_results(tmp_path):
    from dstenv.io import output_folder

    data = tmp_path / "data"
    (data / "train").mkdir(parents=True)
    (data / "manifest.json").write_text('{"format": "dstenv-manifest"}')
    runs = tmp_path / "run"
    runs.mkdir()
    (runs / "best.pt").write_bytes(b"\0")
    root = tmp_path / "kitti"
    (root / "training" / "velodyne").mkdir(parents=True)
    (tmp_path / "file").write_text("x")
    bad = [  # (path, kwargs, message)
        ("", {}, r"--out: empty; give a folder \(\. for the current one\)"),
        (" ", {"dataset": True}, "empty"),
        (tmp_path / "file", {}, "is a file; give a folder"),
        (tmp_path / "file" / "sub", {}, "cannot create its folder"),
        (data, {}, "is the dataset folder"),  # checkpoints or a report into a dataset
        (data / "train", {"dataset": True}, "inside the dataset folder"),
        (data / "x" / "y", {}, "inside the dataset folder"),
        (runs, {"dataset": True}, "holds best.pt"),
        (root, {"dataset": True, "inputs": (("--root", root),)}, "is the input --root"),
        (root / "training" / "velodyne", {"dataset": True, "inputs": (("--root", root),)},
         "inside the input --root"),
    ]
    for path, kw, msg in bad:
        with pytest.raises(ValueError, match=msg):
            output_folder(path, "--out", **kw)
    # what stays allowed: a dataset resumed, results beside data, a new folder
    assert output_folder(data, "--out", dataset=True) == data
    assert output_folder(runs, "--out") == runs
    assert output_folder(tmp_path / "new" / "deep", "--out", dataset=True,
                         inputs=(("--root", root),)) == tmp_path / "new" / "deep"
    assert not (tmp_path / "new").exists()  # nothing made


def test_what_makes_a_dataset_folder_and_links_do_not_hide_one(tmp_path):
    """Attack 15: a killed train's own lock made its folder 'a dataset' (no resume); a web
    app's manifest.json blocked every output below it; a symlink or .. got round the
    check; a broken link and a read-only folder were found only at the first write."""
    from dstenv.io import is_dataset_folder, made_folders, output_folder, remove_made

    run = tmp_path / "run"
    run.mkdir()
    (run / ".dstenv.lock").write_text("123\n")  # a train killed: its lock, its checkpoints
    (run / "last.pt").write_bytes(b"\0")
    assert not is_dataset_folder(run)
    assert output_folder(run, "--out") == run  # the rerun resumes
    app = tmp_path / "app"
    app.mkdir()
    (app / "manifest.json").write_text('{"name": "my web app"}')
    assert output_folder(app / "runs" / "a", "--out") == app / "runs" / "a"
    ds = tmp_path / "ds"
    (ds / "train").mkdir(parents=True)
    (ds / "manifest.json").write_text('{"format": "dstenv-manifest", "frames": 1}')
    writing = tmp_path / "writing"  # a generate still running: its lock beside a split
    (writing / "val").mkdir(parents=True)
    (writing / ".dstenv.lock").write_text("1\n")
    assert is_dataset_folder(ds) and is_dataset_folder(writing)
    (tmp_path / "link").symlink_to(ds / "train")
    (tmp_path / "deep").mkdir()
    for path in (tmp_path / "link", tmp_path / "link" / ".." / "sneaky", writing / "x"):
        with pytest.raises(ValueError, match="(inside|is) the dataset folder"):
            output_folder(path, "--out")
    with pytest.raises(ValueError, match="inside the input --root"):
        output_folder(tmp_path / "link" / "out", "--out", dataset=True,
                      inputs=(("--root", ds),))
    (tmp_path / "broken").symlink_to(tmp_path / "nowhere")
    with pytest.raises(ValueError, match="--out .*broken: is a broken symbolic link"):
        output_folder(tmp_path / "broken", "--out")
    real = os.open
    with pytest.MonkeyPatch.context() as mp:  # a read-only folder: found by the probe
        mp.setattr(os, "open", lambda p, f, *a, **k: (_ for _ in ()).throw(
            OSError(errno.EROFS, "Read-only file system")) if f & os.O_CREAT else real(p, f, *a))
        with pytest.raises(ValueError, match=r"--out .*ro/t: cannot create a file in .* "
                                             r"\(Read-only file system\)"):
            output_folder(tmp_path / "ro" / "t", "--out")
    # a failed run takes away the folders it made, never one that was there
    top = made_folders(tmp_path / "new1" / "new2" / "new3")
    (tmp_path / "new1" / "new2" / "new3").mkdir(parents=True)
    remove_made(tmp_path / "new1" / "new2" / "new3", top)
    assert not (tmp_path / "new1").exists() and (tmp_path / "deep").is_dir()
    assert made_folders(tmp_path / "deep") is None
    remove_made(tmp_path / "deep", None)
    assert (tmp_path / "deep").is_dir()
