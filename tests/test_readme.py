"""Every ```python block of the README runs as written, and the set-up is two commands.

A snippet that fails for a new user is a bug of the documentation; each block runs
in a fresh interpreter in an empty folder, with nothing imported beforehand.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```python\n(.*?)```", README, re.S)


def test_readme_has_exactly_the_two_setup_commands():
    lines = [ln for ln in README.splitlines() if re.search(r"# (main job|tests)$", ln)]
    assert [ln.rsplit("# ", 1)[1] for ln in lines] == ["main job", "tests"], lines
    assert all(ln.startswith("pip install torch==2.13.0 && pip install -e ") for ln in lines)


def test_readme_has_python_blocks():
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_python_block_runs(index, tmp_path):
    code = BLOCKS[index]
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600, env={**os.environ, "MPLBACKEND": "Agg"})
    assert out.returncode == 0, f"README python block {index + 1}:\n{code}\n{out.stderr[-3000:]}"
