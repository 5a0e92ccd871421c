"""The dstenv command: version, help, bench, errors."""

import os
import re
import subprocess
import sys

import pytest

from dstenv import __version__
from dstenv.cli import main


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"dstenv {__version__}"


def test_console_script_help():
    out = subprocess.run([sys.executable, "-m", "dstenv.cli", "--help"],
                         capture_output=True, text=True)
    assert out.returncode == 0 and "bench" in out.stdout


def test_bench_fusion_quick(capsys, tmp_path):
    out = tmp_path / "bench.json"
    assert main(["bench", "fusion", "--quick", "--repeats", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "256x256" in text and out.exists()


def test_bench_json_path_is_checked_before_timing(capsys, tmp_path):
    # a missing folder is created (as render and generate do); a directory or a path
    # under a file fails at once, in one line, not after the benchmark has run
    out = tmp_path / "new" / "dir" / "bench.json"
    assert main(["bench", "fusion", "--quick", "--repeats", "1", "--json", str(out)]) == 0
    assert out.exists()
    capsys.readouterr()
    assert main(["bench", "fusion", "--quick", "--json", str(tmp_path)]) == 2
    out_, err = capsys.readouterr()
    assert "is a directory" in err and err.count("\n") == 1 and "== bench" not in out_
    assert main(["bench", "fusion", "--quick", "--json", ""]) == 2  # was silently no file
    assert "--json: empty; give a file name" in capsys.readouterr().err
    assert main(["bench", "fusion", "--quick", "--goals"]) == 2  # was silently ignored
    assert "--goals goes with bench data" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    assert main(["bench", "fusion", "--quick", "--json", str(tmp_path / "file" / "b.json")]) == 2
    out_, err = capsys.readouterr()
    assert "cannot create its folder" in err and "== bench" not in out_


def test_bench_keeps_its_results_when_the_json_cannot_be_written(capsys, tmp_path,
                                                                 monkeypatch):
    import json

    import dstenv.bench
    import dstenv.io

    monkeypatch.setattr(dstenv.bench, "run_benchmark", lambda name, args: {"rate": 7.5})

    def refuse(path, text):
        raise PermissionError(1, "Operation not permitted", str(path))

    monkeypatch.setattr(dstenv.io, "atomic_write_text", refuse)
    assert main(["bench", "fusion", "--json", str(tmp_path / "b.json")]) == 2
    err = capsys.readouterr().err
    assert "cannot write it (Operation not permitted); the results are in" in err
    kept = err.rsplit("the results are in ", 1)[1].split()[0]
    try:
        assert json.loads(open(kept).read()) == {"fusion": {"rate": 7.5}}
    finally:
        os.unlink(kept)


def test_an_interrupted_bench_does_not_promise_a_resume(capsys, monkeypatch):
    import dstenv.bench

    def interrupted(name, args):
        raise KeyboardInterrupt

    monkeypatch.setattr(dstenv.bench, "run_benchmark", interrupted)
    assert main(["bench", "fusion"]) == 130
    err = capsys.readouterr().err
    assert "interrupted; nothing to resume: rerun the command" in err and "kept" not in err


def test_an_interrupted_bench_all_keeps_the_finished_benchmarks(capsys, monkeypatch, tmp_path):
    import json

    import dstenv.bench

    def first_only(name, args):
        if name != "fusion":
            raise KeyboardInterrupt
        return {"rate": 1.0}

    monkeypatch.setattr(dstenv.bench, "run_benchmark", first_only)
    out = tmp_path / "all.json"
    assert main(["bench", "all", "--json", str(out)]) == 130
    assert "the finished benchmarks (fusion) are in" in capsys.readouterr().err
    assert json.loads(out.read_text()) == {"fusion": {"rate": 1.0}, "interrupted": True}


def test_bench_refuses_negative_repeats(capsys):
    assert main(["bench", "fusion", "--quick", "--repeats", "-1"]) == 2
    out, err = capsys.readouterr()
    assert "--repeats must be >= 0" in err and "== bench" not in out


def test_unknown_bench_is_rejected(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bench", "nope"])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


HEAVY = ("torch", "scipy", "numba", "dstenv.kitti.readers", "dstenv.segment.registry",
         "dstenv.data.shards", "h5py", "matplotlib")


@pytest.mark.parametrize("argv", [["--version"], ["--help"], []])
def test_top_level_cli_is_light(argv):
    code = ("import sys\nfrom dstenv.cli import main\n"
            f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
            f"print('LOADED', [m for m in {HEAVY!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "LOADED []" in out.stdout, out.stdout


def test_subcommand_loads_only_its_module():
    code = ("import sys\nfrom dstenv.cli import main\n"
            "try:\n    main(['render', '--help'])\nexcept SystemExit:\n    pass\n"
            "print('LOADED', [m for m in ('torch', 'dstenv.segment.cli', "
            "'dstenv.segment.bench_cli', 'dstenv.kitti.cli') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert "--scenario" in out.stdout and "LOADED []" in out.stdout, out.stdout + out.stderr


def test_help_lists_every_command(capsys):
    from dstenv.cli import COMMANDS

    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    for name, (_, help_text) in COMMANDS.items():
        assert name in text and help_text.split()[0] in text


def test_expected_errors_are_one_line(capsys, tmp_path):
    assert main(["info", str(tmp_path / "nothing-here")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("dstenv info: error:") and "\n" not in err and "nothing-here" in err


@pytest.mark.parametrize("argv, line", [
    (["render", "--out", "x.png", "--senario", "dense"], "dstenv render: error: unrecognized "
     "arguments: --senario dense; did you mean --scenario? (see dstenv render --help)"),
    (["render", "--senario", "dense", "--outt", "x.png"], "dstenv render: error: the following "
     "arguments are required: --out (--senario is no option); did you mean --scenario?"),
    (["generate", "--frame", "10"], "dstenv generate: error: ambiguous option: --frame could "
     "match --frames, --frames-per-shard (see dstenv generate --help)"),
    (["kitti", "render", "--root", "r", "--sequence", "3", "--frame", "1", "--out", "x.png",
      "--zzz"],
     "dstenv kitti render: error: unrecognized arguments: --zzz (see dstenv kitti render "
     "--help)"),
    (["bogus"], "dstenv: error: argument COMMAND: invalid choice: 'bogus'"),
])
def test_command_line_mistakes_are_one_line_under_their_command(capsys, argv, line):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    assert exc.value.code == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(line), err  # (argparse printed the usage first, the top level's)


def test_worker_tracebacks_become_one_line(capsys, monkeypatch):
    import dstenv.cli as cli

    msg = ("Caught ValueError in DataLoader worker process 0.\nOriginal Traceback (most recent "
           "call last):\n  File \"x.py\", line 1, in f\n    g()\nValueError: shard.h5: bad chunk\n")
    assert cli.one_line(ValueError(msg)) == ("Caught ValueError in DataLoader worker process "
                                              "0. ValueError: shard.h5: bad chunk")


@pytest.mark.parametrize("command", ["bench", "render", "kitti", "generate", "train"])
def test_help_shows_no_rst_markup(capsys, command):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    out = capsys.readouterr().out
    assert "``" not in out and not re.search(r":[a-z]+:`", out) and "\n::\n" not in out


@pytest.mark.parametrize("cmd, message", [
    (["kitti", "convert", "--root", "{root}", "--sequences", "3", "--out", "{root}"],
     "is the input --root"),
    (["kitti", "convert", "--root", "{root}", "--sequences", "3", "--out",
      "{root}/training/velodyne"], "inside the input --root"),
    (["train", "--data", "{data}", "--out", "{other}"], "is the dataset folder"),
    (["kitti", "evaluate", "--data", "{data}", "--out", "{other}"], "is the dataset folder"),
    (["export-kitti", "--frames", "5", "--out", "{data}"], "is the dataset folder"),
    (["generate", "--frames", "4", "--out", "{runs}"], "holds best.pt"),
    (["benchmark", "--data", "{data}", "--out", ""], "--out: empty; give a folder"),
    (["train", "--data", "{data}", "--out", " "], "--out: empty; give a folder"),
])
def test_outputs_never_mix_with_inputs_datasets_or_results(tmp_path, capsys, cmd, message):
    """Attack 14: outputs were accepted inside the KITTI root, in another dataset, and a
    dataset in a checkpoint folder; an empty --out meant the current folder."""
    root, data, other, runs = (tmp_path / n for n in ("kitti", "data", "other", "runs"))
    (root / "training" / "velodyne").mkdir(parents=True)
    for d in (data, other):
        d.mkdir()
        (d / "manifest.json").write_text('{"format": "dstenv-manifest"}')
    runs.mkdir()
    (runs / "best.pt").write_bytes(b"\0")
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    args = [a.format(root=root, data=data, other=other, runs=runs) for a in cmd]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before
