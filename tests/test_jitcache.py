"""dstenv._jitcache: numba's disk cache sees a change in a kernel's imported module."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from dstenv import _jitcache

pytest.importorskip("numba")

CALLER = """
import numba
from jcpkg.callee import answer
from jcpkg import consts

@numba.njit(cache=True)
def total():
    return answer() + consts.OFFSET
"""

RUN = """
import sys
from dstenv import _jitcache
if sys.argv[2] == "on":
    _jitcache.register_package("jcpkg", sys.argv[1] + "/jcpkg")
    _jitcache.install()
sys.path.insert(0, sys.argv[1])
from jcpkg.caller import total
print(total())
"""


def _package(root: Path, answer: int, offset: int) -> None:
    pkg = root / "jcpkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(CALLER)
    (pkg / "callee.py").write_text(textwrap.dedent(f"""
        import numba

        @numba.njit(cache=True)
        def answer():
            return {answer}
        """))
    (pkg / "consts.py").write_text(f"OFFSET = {offset}\n")


def _total(root: Path, mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", RUN, str(root), mode], check=True,
                         capture_output=True, text=True, timeout=300)
    return int(out.stdout.strip())


def test_a_changed_callee_or_constant_recompiles_the_cached_caller(tmp_path: Path) -> None:
    _package(tmp_path, answer=1, offset=10)
    assert _total(tmp_path, "on") == 11
    assert list((tmp_path / "jcpkg" / "__pycache__").glob("caller.total-*.nbi"))
    _package(tmp_path, answer=2, offset=10)  # only the callee's file changes
    assert _total(tmp_path, "on") == 12
    _package(tmp_path, answer=2, offset=30)  # only the constant's module changes
    assert _total(tmp_path, "on") == 32


def test_numba_alone_keeps_the_stale_caller(tmp_path: Path) -> None:
    """The bug the locator mends (if numba ever mends it, this test says so)."""
    _package(tmp_path, answer=1, offset=10)
    assert _total(tmp_path, "off") == 11
    _package(tmp_path, answer=2, offset=10)
    assert _total(tmp_path, "off") == 11


def test_dependency_files_follow_imports_and_reexports() -> None:
    root = Path(_jitcache.__file__).parent
    deps = {p.relative_to(root).as_posix() for p in _jitcache.dependency_files(
        root / "sim" / "traffic.py")}
    assert {"sim/traffic.py", "sim/routing.py", "sim/lanes.py", "sim/types.py"} <= deps
    assert "sim/__init__.py" not in deps and "envs/env.py" not in deps
    # a re-export through dst/__init__.py leads to the defining module only
    raycast = {p.relative_to(root).as_posix() for p in _jitcache.dependency_files(
        root / "sensing" / "raycast.py")}
    assert "dst/frame.py" in raycast and "dst/__init__.py" not in raycast


def test_installed_once_in_front_of_numbas_locators() -> None:
    import numba  # noqa: F401  (importing dstenv arranged the install on import)
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    assert _jitcache.install() is True
    names = [c.__name__ for c in impl._locator_classes]
    assert names[0].startswith("Package") and sum(n.startswith("Package") for n in names) == len(
        [n for n in names if not n.startswith("Package") and f"Package{n}" in names])


def test_kernels_cached_looks_in_tree_and_user_wide(tmp_path: Path, monkeypatch) -> None:
    import numba.core.config as nb_config

    from dstenv._jitcache import kernels_cached

    pkg = tmp_path / "pkgx"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    user = tmp_path / "user"
    monkeypatch.setattr(nb_config, "CACHE_DIR", str(user))
    assert not kernels_cached(pkg)  # fresh install: nothing compiled yet
    (user / "other" / "x.nbi").parent.mkdir(parents=True)
    (user / "other" / "x.nbi").write_bytes(b"")
    assert not kernels_cached(pkg)  # another package's kernels do not count
    (user / "pkgx_sub_1234" / "k.nbi").parent.mkdir(parents=True)
    (user / "pkgx_sub_1234" / "k.nbi").write_bytes(b"")
    assert kernels_cached(pkg)
    monkeypatch.setattr(nb_config, "CACHE_DIR", str(tmp_path / "none"))
    (pkg / "sub" / "__pycache__" / "k.nbi").write_bytes(b"")
    assert kernels_cached(pkg)
