"""The dstenv command: version, help, bench, errors."""

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
    out = subprocess.run([sys.executable, "-m", "dstenv.cli", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "bench" in out.stdout


def test_bench_fusion_quick(capsys, tmp_path):
    out = tmp_path / "bench.json"
    assert main(["bench", "fusion", "--quick", "--repeats", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "256x256" in text and out.exists()


def test_unknown_bench_is_rejected(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bench", "nope"])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
