"""Atomic file writes, and the checks of output paths: the one home of both for
every writer of dstenv.

A file appears under its final name complete or not at all: the data go to
``NAME.partial`` in the same folder (same file system, so the rename is atomic),
the file is flushed and fsynced, renamed over ``NAME``, and the folder is fsynced
so the rename itself survives a power cut. On any error the partial file is
removed and the previous ``NAME``, if any, is left untouched.

Before any work, :func:`output_file`, :func:`png_path` and :func:`output_folder` refuse
an output that cannot be written or whose files would mix with others' (inside a
dataset, inside an input, a dataset into a results folder), in one line naming the
option.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["PARTIAL_SUFFIX", "partial_path", "atomic_path", "atomic_write_bytes",
           "atomic_write_text", "fsync_file", "fsync_dir", "is_dataset_folder", "made_folders",
           "output_file", "output_folder", "png_path", "remove_made"]

#: suffix of a file being written; never a final file (readers and scans skip it)
PARTIAL_SUFFIX = ".partial"


def partial_path(path: str | Path) -> Path:
    """Where :func:`atomic_path` writes ``path`` before the rename: ``NAME.partial``."""
    path = Path(path)
    return path.with_name(path.name + PARTIAL_SUFFIX)


def fsync_file(path: str | Path) -> None:
    """Flush ``path``'s data to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(directory: str | Path) -> None:
    """Flush a folder's entries (a rename) to disk; a no-op where folders cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path: str | Path, fsync: bool = True) -> Iterator[Path]:
    """Write a file atomically: ``with atomic_path(p) as tmp: write(tmp)``.

    The body writes the complete file to ``tmp`` (``p.partial``, parents created);
    on a clean exit ``tmp`` is fsynced and renamed to ``p`` and the folder fsynced;
    on an exception ``tmp`` is deleted and ``p`` keeps its old content.
    A writer that picks the format from the suffix (matplotlib) must be told it.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = partial_path(path)
    try:
        yield tmp
        if fsync:
            fsync_file(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if exc.filename is None and exc.errno is not None:  # name the file (disk full...)
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if fsync:
        fsync_dir(path.parent)


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """:func:`atomic_write_bytes` of UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"))


#: a folder holding a ``manifest.json`` of this format is a dstenv dataset
MANIFEST_FORMAT = "dstenv-manifest"
#: files that make a folder a training run's or a benchmark's (never a dataset's)
RESULT_MARKERS = ("best.pt", "last.pt", "results.json")


def is_dataset_folder(folder: Path) -> bool:
    """Whether ``folder`` holds a dstenv dataset: its manifest (another program's
    ``manifest.json``, a web app's, does not count), or the lock of a run still writing
    one beside its split folders (a training run's own lock does not count)."""
    manifest = folder / "manifest.json"
    if manifest.is_file():
        try:
            with open(manifest, "rb") as fh:
                return f'"{MANIFEST_FORMAT}"'.encode() in fh.read(1 << 16)
        except OSError:
            return False
    return (folder / ".dstenv.lock").is_file() and any(
        (folder / split).is_dir() for split in ("train", "val", "test"))


def _refuse_inside(out: Path, option: str, inputs: tuple[tuple[str, str | Path], ...],
                   self_too: bool) -> None:
    """A one-line ValueError when ``out`` lies inside a dataset folder (or is one, with
    ``self_too``) or is, or lies inside, one of ``inputs`` (paths compared resolved:
    a symlink or ``..`` does not get round it; empty inputs are their own checks')."""
    full = Path(os.path.realpath(out))
    for flag, given in inputs:
        if not str(given).strip():
            continue
        src = Path(os.path.realpath(given))
        if full == src or src in full.parents:
            where = "is" if full == src else "inside"
            raise ValueError(f"{option} {out}: {where} the input {flag} {given}; write it "
                             "elsewhere")
    for folder in ((full,) if self_too else ()) + tuple(full.parents):
        if is_dataset_folder(folder):
            where = "is" if folder == full else "inside"
            raise ValueError(f"{option} {out}: {where} the dataset folder {folder}; write "
                             "it elsewhere")


def output_folder(path: str | Path, option: str, *, dataset: bool = False,
                  inputs: tuple[tuple[str, str | Path], ...] = ()) -> Path:
    """Refuse, before any work, an output folder whose files would mix with others'.

    Args:
        path: the folder (made later by the writer).
        option: the flag that gave it, for the message.
        dataset: the folder will hold a dataset (its own, when resuming: allowed); else
            checkpoints, a report or a KITTI root, which never go into a dataset.
        inputs: ``(option, path)`` pairs of input folders it must stay out of.

    Raises:
        ValueError: one line naming ``option``, the path and the fix: an empty value
            (usually an unset shell variable), a file or a broken link, a folder where
            no file can be made (probed), a place inside a dataset or an input, a
            dataset folder for other files, or a checkpoint/report folder for a dataset.
    """
    if not str(path).strip():
        raise ValueError(f"{option}: empty; give a folder (. for the current one)")
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{option} {out}: is a file; give a folder")
    if not out.exists() and os.path.lexists(out):
        raise ValueError(f"{option} {out}: is a broken symbolic link; give a folder")
    _writable(out / "x", option, shown=out)
    _refuse_inside(out, option, inputs, self_too=not dataset)
    if dataset and out.is_dir():
        found = [m for m in RESULT_MARKERS if (out / m).is_file()]
        if found:
            raise ValueError(f"{option} {out}: holds {found[0]} (a training run's or a "
                             "benchmark's folder); give another folder for the dataset")
    return out


def made_folders(out: str | Path) -> Path | None:
    """The topmost of ``out`` and its parents that does not exist yet (what a writer
    will make), or None: :func:`remove_made` takes them away again after a failure."""
    top = None
    for folder in (Path(out), *Path(out).parents):
        if folder.exists():
            break
        top = folder
    return top


def remove_made(out: str | Path, top: Path | None) -> None:
    """Remove ``out`` and its parents up to ``top`` (from :func:`made_folders`) while
    they are empty folders; never a folder that was there before."""
    if top is None:
        return
    for folder in (Path(out), *Path(out).parents):
        try:
            folder.rmdir()  # only when empty
        except OSError:
            return
        if folder == top:
            return


def png_path(path: str | Path, option: str = "--out") -> Path:
    """``path`` as a :class:`Path` if it names a ``.png`` file (the renderers write PNG).

    Raises:
        ValueError: another suffix (a ``.jpg`` name would hold PNG bytes), naming the fix.
    """
    if not str(path).strip():
        raise ValueError(f"{option}: empty; give a file name ending in .png")
    out = Path(path)
    if out.suffix.lower() != ".png":
        raise ValueError(f"{option} {out}: the picture is a PNG; give a name ending in .png")
    if out.is_dir():  # before any work, not when the picture is written
        raise ValueError(f"{option} {out}: is a directory; give a file name ending in .png")
    _refuse_inside(out, option, (), self_too=False)
    _replaceable(out, option, "a PNG picture", _is_png)
    _writable(out, option)
    return out


def _is_png(path: Path) -> bool:
    with open(path, "rb") as fh:
        return fh.read(8) == b"\x89PNG\r\n\x1a\n"


def _nearest_folder(out: Path, option: str, shown: Path | None = None) -> Path:
    """The nearest existing folder above ``out`` (where its folders would be made).

    Raises:
        ValueError: that path is a file, not a folder (naming ``option`` and ``shown``)."""
    parent = out.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{option} {out if shown is None else shown}: cannot create its "
                         f"folder ({parent} is a file)")
    return parent


def _writable(out: Path, option: str, shown: Path | None = None) -> None:
    """A one-line ValueError (naming ``shown``, default ``out``) when no file ``out``
    can be made: its nearest existing folder is a file, is not writable (or marked
    read-only for everyone: root could write into a shared data folder), or refuses a
    new file (a probe made there and removed at once: root's access() says yes in /proc
    or on a read-only mount)."""
    shown = out if shown is None else shown
    parent = _nearest_folder(out, option, shown)
    mode = parent.stat().st_mode
    if not os.access(parent, os.W_OK | os.X_OK) or not mode & 0o222:  # root may, won't
        raise ValueError(f"{option} {shown}: {parent} is not writable ({stat.filemode(mode)}); "
                         "give a path you can write to")
    try:
        fd, probe = tempfile.mkstemp(dir=parent, prefix=".dstenv-", suffix=".probe")
    except OSError as exc:
        raise ValueError(f"{option} {shown}: cannot create a file in {parent} "
                         f"({exc.strerror}); give a path you can write to") from None
    os.close(fd)
    os.unlink(probe)


def output_file(path: str | Path, option: str,
                inputs: tuple[tuple[str, str | Path], ...] = ()) -> Path:
    """Refuse, before any work, an output ``path`` that cannot become a file: a directory,
    or a path under a file, or a folder where no file can be made (an empty probe file
    is made there and removed at once), or a place among a dataset's files or inside an
    input (``inputs``: ``(option, path)`` pairs, e.g. ``("--root", root)``). Nothing
    else is created (the atomic writers make the folder).

    Raises:
        ValueError: one line naming ``option``, the path and the fix.
    """
    if not str(path).strip():
        raise ValueError(f"{option}: empty; give a file name")
    out = Path(path)
    if out.is_dir():
        raise ValueError(f"{option} {out}: is a directory; give a file name")
    _refuse_inside(out, option, inputs, self_too=False)
    _replaceable(out, option, "a report (JSON or CSV)", _is_report)
    _writable(out, option)
    return out


def _is_report(path: Path) -> bool:
    """A text file that a report may replace: JSON, or a CSV table (by its name or its
    header line)."""
    with open(path, "rb") as fh:
        data = fh.read(64 << 20)
    if b"\0" in data[:4096]:
        return False
    if path.suffix.lower() == ".csv" or (path.suffix.lower() in ("", ".txt")
                                         and b"," in data.split(b"\n", 1)[0]):  # a header
        return True
    try:
        json.loads(data)
    except ValueError:
        return False
    return True


def _replaceable(out: Path, option: str, kind: str, same_kind: Any) -> None:
    """A one-line ValueError when an existing ``out`` may not be replaced: anything but a
    regular file (the atomic rename would put a file in place of a device such as
    /dev/null, a pipe or a link), or a file that is not ``kind`` (``same_kind(path)``)."""
    if not os.path.lexists(out):
        return
    if out.is_symlink() or not out.is_file():
        raise ValueError(f"{option} {out}: exists and is not a regular file (a device, a "
                         "pipe or a link); give a new file name")
    if not same_kind(out):
        raise ValueError(f"{option} {out}: exists and is not {kind}; give a new file name "
                         "(or remove it)")

