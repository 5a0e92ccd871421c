"""Numba's on-disk cache, invalidated when a kernel's imports change.

numba keys a cached kernel (``@numba.njit(cache=True)``) on its own source file only.
A kernel that calls a jitted function of another module, or reads a constant from
one, keeps its old machine code when only that other module changes: after a ``git
pull`` into an editable install, or a ``pip install --upgrade`` (pip leaves the
``__pycache__/*.nbi`` files behind), dstenv would run stale code without a word.

:func:`install` puts, in front of numba's cache locators, one that serves the source
files of registered packages (dstenv itself) and stamps each cache entry with the
file's own stamp *and* a hash of every module of the package that the file imports,
directly or through other package modules. A change anywhere in that closure makes
numba see a stale index and recompile; nothing is deleted, and the cache stays where
numba would put it (``__pycache__`` next to the source, else the user-wide cache).
Other packages' kernels are untouched.

Uses numba's locator classes (``numba.core.caching``), which are internal: when they
are not found, :func:`install` returns ``False`` and numba's default applies.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.abc
import importlib.util
import re
import sys
from pathlib import Path

__all__ = ["install", "install_when_imported", "dependency_files", "register_package",
           "kernels_cached"]

_ROOTS: dict[str, Path] = {}  # package name -> package directory


def register_package(name: str, directory: str | Path) -> None:
    """Serve the kernels of package ``name`` (importable from ``directory``)."""
    _ROOTS[name] = Path(directory).resolve()
    for cached in (_import_nodes, _imports, _closure, _file_digest, _stamp):
        cached.cache_clear()


def _owner(path: Path) -> str | None:
    for name, root in _ROOTS.items():
        if path == root or root in path.parents:
            return name
    return None


def _module_file(name: str) -> Path | None:
    """File of the package module ``name`` (dotted), or None outside the packages."""
    top, _, rest = name.partition(".")
    root = _ROOTS.get(top)
    if root is None:
        return None
    base = root.joinpath(*rest.split(".")) if rest else root
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _module_name(path: Path) -> str:
    top = _owner(path)
    parts = list(path.relative_to(_ROOTS[top]).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join([top, *parts])


def _absolute(path: Path, node: ast.ImportFrom) -> str:
    """Dotted module of ``from X import ...`` in ``path``, relative ones resolved."""
    if not node.level:
        return node.module or ""
    here = _module_name(path)
    package = (here if path.name == "__init__.py" else here.rpartition(".")[0]).split(".")
    base = package[:len(package) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


_IMPORT = re.compile(r"^(?:from[ \t]+[\w.]+[ \t]+import[ \t]+(?:\([^)]*\)|[^\n]*)"
                     r"|import[ \t]+[^\n]*)", re.MULTILINE)


@functools.lru_cache(maxsize=None)
def _import_nodes(path: Path) -> tuple[ast.stmt, ...]:
    """The module-level import statements of ``path`` (at column 0, where a kernel's
    constants and callees are bound; numba allows no import inside a kernel). Only
    those lines are parsed: parsing whole modules cost ~0.7 s per process."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return ()
    try:
        return tuple(ast.parse("\n".join(_IMPORT.findall(text))).body)
    except SyntaxError:  # an odd import line: parse the whole module
        try:
            return tuple(n for n in ast.parse(text).body
                         if isinstance(n, (ast.Import, ast.ImportFrom)))
        except SyntaxError:
            return ()


def _defining_file(module: str, name: str, depth: int = 0) -> Path | None:
    """File that defines ``module.name``: the submodule itself, or for a name that a
    package's ``__init__`` re-exports, the module it comes from (not the whole
    package, whose ``__init__`` imports everything)."""
    sub = _module_file(f"{module}.{name}")
    if sub is not None:
        return sub
    file = _module_file(module)
    if file is None or file.name != "__init__.py" or depth > 8:
        return file
    for node in _import_nodes(file):
        if not isinstance(node, ast.ImportFrom):
            continue
        for alias in node.names:
            if (alias.asname or alias.name) == name:
                found = _defining_file(_absolute(file, node), alias.name, depth + 1)
                return found if found is not None else file
    return file


@functools.lru_cache(maxsize=None)
def _imports(path: Path) -> frozenset[Path]:
    """Package files that ``path`` imports at module level (``import a.b``, ``from a
    import b``, relative imports), with re-exports of ``__init__`` files followed."""
    found: set[Path] = set()
    for node in _import_nodes(path):
        if isinstance(node, ast.Import):
            files = [_module_file(alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = _absolute(path, node)
            files = [_defining_file(module, alias.name) for alias in node.names
                     if alias.name != "*"]
            if any(alias.name == "*" for alias in node.names):
                files.append(_module_file(module))
        else:
            continue
        found.update(f for f in files if f is not None and f != path)
    return frozenset(found)


@functools.lru_cache(maxsize=None)
def _closure(path: Path) -> tuple[Path, ...]:
    seen = {path}
    todo = [path]
    while todo:
        for dep in _imports(todo.pop()):
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return tuple(sorted(seen))


def dependency_files(source: str | Path) -> list[Path]:
    """Package files whose contents a kernel in ``source`` may depend on: the file
    itself and every package module it imports, transitively (sorted)."""
    path = Path(source).resolve()
    return list(_closure(path)) if _owner(path) is not None else [path]


@functools.lru_cache(maxsize=None)
def _file_digest(path: Path) -> bytes:
    """sha256 of one file, read once per process however many closures hold it."""
    return hashlib.sha256(path.read_bytes()).digest()


@functools.lru_cache(maxsize=None)
def _stamp(path: Path) -> str:
    digest = hashlib.sha256()
    for file in _closure(path):
        digest.update(str(file.relative_to(_ROOTS[_owner(file)])).encode())
        digest.update(_file_digest(file))
    return digest.hexdigest()


def _wrap(base: type) -> type:
    class PackageLocator(base):  # type: ignore[misc, valid-type]
        @classmethod
        def from_function(cls, py_func, py_file):  # noqa: ANN001, ANN206
            if _owner(Path(py_file).resolve()) is None:
                return None
            return super().from_function(py_func, py_file)

        def get_source_stamp(self):  # noqa: ANN202
            return (super().get_source_stamp(), _stamp(Path(self._py_file).resolve()))

    PackageLocator.__name__ = PackageLocator.__qualname__ = f"Package{base.__name__}"
    return PackageLocator


def install() -> bool:
    """Put the package-aware locators in front of numba's (once). Returns whether
    numba's locator machinery was found."""
    try:
        from numba.core import caching
    except ImportError:
        return False
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    mixin = getattr(caching, "_SourceFileBackedLocatorMixin", None)
    classes = getattr(impl, "_locator_classes", None)
    if impl is None or mixin is None or not isinstance(classes, list):
        return False
    if any(getattr(c, "_dstenv_wrapped", False) for c in classes):
        return True
    ours = []
    for base in classes:
        if isinstance(base, type) and issubclass(base, mixin):
            wrapped = _wrap(base)
            wrapped._dstenv_wrapped = True
            ours.append(wrapped)
    impl._locator_classes = ours + classes
    return True


class _AfterNumba(importlib.abc.MetaPathFinder):
    """Runs :func:`install` right after ``numba`` is first imported, so that
    ``import dstenv`` does not itself import numba (0.7 s)."""

    def find_spec(self, name, path=None, target=None):  # noqa: ANN001, ANN201
        if name != "numba":
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.util.find_spec("numba")
        loader = getattr(spec, "loader", None)
        if loader is None or not hasattr(loader, "exec_module"):
            return spec
        run = loader.exec_module

        def exec_module(module):  # noqa: ANN001, ANN202
            run(module)
            install()

        loader.exec_module = exec_module
        return spec


def install_when_imported() -> None:
    """:func:`install` now if numba is imported, else as soon as it is."""
    if "numba" in sys.modules:
        install()
    elif not any(isinstance(f, _AfterNumba) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumba())


def kernels_cached(package_dir: str | Path) -> bool:
    """Whether numba's on-disk cache holds any kernel of the package in ``package_dir``:
    in ``__pycache__`` next to its sources, or in the user-wide cache (``NUMBA_CACHE_DIR``
    or ``~/.cache/numba``) under a folder named after it. False on a fresh install, whose
    first run compiles every kernel it uses (about a minute for data generation)."""
    root = Path(package_dir).resolve()
    if next(root.glob("**/__pycache__/*.nbi"), None) is not None:
        return True
    try:
        from numba.core.config import CACHE_DIR
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    user = Path(CACHE_DIR) if CACHE_DIR else Path.home() / ".cache" / "numba"
    return user.is_dir() and any(root.name in str(p.relative_to(user))
                                 for p in user.glob("**/*.nbi"))

