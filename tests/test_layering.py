"""Architecture rules that code review alone would miss."""

import ast
import tomllib
from pathlib import Path

import pytest

import dstenv

PKG = Path(dstenv.__file__).parent
ROOT = PKG.parent
CORE = ["dst", "sim", "sensing", "grid.py", "frame.py", "pipeline.py", "config.py"]


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("part", CORE)
def test_core_never_imports_gym(part):
    target = PKG / part
    files = sorted(target.rglob("*.py")) if target.is_dir() else [target] if target.exists() else []
    for f in files:
        if f.name in ("highway.py", "highway_map.py"):  # the sim's highway-env adapter
            continue
        bad = _imports(f) & {"gymnasium", "gym", "stable_baselines3", "highway_env"}
        assert not bad, f"{f.relative_to(ROOT)} imports {bad}"


def test_every_subpackage_is_packaged():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(pyproject["tool"]["setuptools"]["packages"])
    found = {"dstenv"} | {
        "dstenv." + ".".join(p.parent.relative_to(PKG).parts)
        for p in PKG.rglob("__init__.py")
        if p.parent != PKG
    }
    assert found - listed == set(), f"add to [tool.setuptools] packages: {sorted(found - listed)}"


def test_module_sizes():
    too_big = [
        (str(f.relative_to(ROOT)), n)
        for f in PKG.rglob("*.py")
        if f.name != "_fused.py" and (n := len(f.read_text().splitlines())) > 500
    ]
    assert not too_big, f"split these modules: {too_big}"

