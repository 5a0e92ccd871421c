"""Every third-party module dstenv imports is a declared dependency.

A module imported on a developer's machine only because it happened to be
installed there (scipy, once) breaks every command for new users. This test
reads the requirements from ``pyproject.toml`` itself (not from the installed
metadata, which may be stale) and walks every import of the package, the
baselines and the tests.
"""

from __future__ import annotations

import ast
import functools
import importlib.metadata as md
import re
import sys
from pathlib import Path

import pytest

from dstenv.scenario_files import tomllib

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
# the scripts in baselines/ import their siblings by module name
FIRST_PARTY = {"dstenv", "tests", "baselines", "scenarios", "conftest", "shared_data",
               *(p.stem for p in (ROOT / "baselines").rglob("*.py"))}


def _canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement_name(req: str) -> str:
    return _canonical(re.split(r"[\s<>=!~;\[]", req.strip(), maxsplit=1)[0])


def _declared(*extras: str) -> set[str]:
    project = PYPROJECT["project"]
    reqs = list(project["dependencies"])
    for extra in extras:
        reqs += project["optional-dependencies"][extra]
    return {_requirement_name(r) for r in reqs}


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def _third_party(folder: str) -> dict[str, list[str]]:
    """top-level module -> files under ``folder`` importing it (stdlib, first party skipped)."""
    out: dict[str, list[str]] = {}
    for f in sorted((ROOT / folder).rglob("*.py")):
        for mod in _imports(f) - set(sys.stdlib_module_names) - FIRST_PARTY:
            out.setdefault(mod, []).append(str(f.relative_to(ROOT)))
    return out


@functools.cache
def _installed() -> dict[str, list[str]]:
    return md.packages_distributions()


def _distributions(module: str) -> set[str]:
    dists = _installed().get(module)
    # a module that is not installed here (an extra not installed) maps to its own name
    return {_canonical(d) for d in dists} if dists else {_canonical(module)}


@pytest.mark.parametrize("folder, extras", [
    ("dstenv", ("ray",)),  # the Ray backend imports ray only when asked for
    ("baselines", ()),
    ("tests", ("test", "ray")),
])
def test_every_import_is_declared(folder, extras):
    declared = _declared(*extras)
    missing = {mod: files[:3] for mod, files in _third_party(folder).items()
               if not _distributions(mod) & declared}
    assert not missing, (f"imported but not declared in pyproject.toml "
                         f"(dependencies or extras {extras}): {missing}")


def test_the_check_catches_an_undeclared_module(tmp_path):
    # the walker must see a plain import, an aliased one and a from-import
    f = tmp_path / "m.py"
    f.write_text("import scipy.ndimage as nd\nfrom yaml import safe_load\nimport os\n")
    assert _imports(f) == {"scipy", "yaml", "os"}
    assert _distributions("yaml") & {"pyyaml"} or _distributions("yaml") == {"yaml"}
    assert "scipy" in _declared()


def test_core_extra_names_are_installed_distributions():
    # every core requirement resolves in this environment (pip install -e . worked)
    for name in _declared():
        if name == "tomli":
            continue  # python < 3.11 only
        assert md.distribution(name) is not None
