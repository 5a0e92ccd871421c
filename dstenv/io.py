"""Atomic file writes: the one helper every writer of dstenv uses.

A file appears under its final name complete or not at all: the data go to
``NAME.partial`` in the same folder (same file system, so the rename is atomic),
the file is flushed and fsynced, renamed over ``NAME``, and the folder is fsynced
so the rename itself survives a power cut. On any error the partial file is
removed and the previous ``NAME``, if any, is left untouched.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["PARTIAL_SUFFIX", "partial_path", "atomic_path", "atomic_write_bytes",
           "atomic_write_text", "fsync_file", "fsync_dir", "output_file", "output_folder",
           "png_path"]

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


#: files that make a folder a dstenv dataset: its manifest, or the lock of a run writing it
DATASET_MARKERS = ("manifest.json", ".dstenv.lock")
#: files that make a folder a training run's or a benchmark's (never a dataset's)
RESULT_MARKERS = ("best.pt", "last.pt", "results.json")


def _refuse_inside(out: Path, option: str, inputs: tuple[tuple[str, str | Path], ...],
                   self_too: bool) -> None:
    """A one-line ValueError when ``out`` lies inside a dataset folder (or is one, with
    ``self_too``) or is, or lies inside, one of ``inputs``."""
    full = Path(os.path.abspath(out))
    for flag, given in inputs:
        src = Path(os.path.abspath(given))
        if full == src or src in full.parents:
            where = "is" if full == src else "inside"
            raise ValueError(f"{option} {out}: {where} the input {flag} {given}; write it "
                             "elsewhere")
    for folder in ((full,) if self_too else ()) + tuple(full.parents):
        if any((folder / m).is_file() for m in DATASET_MARKERS):
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
            (usually an unset shell variable), a file, a place inside a dataset or an
            input, a dataset folder for other files, or a checkpoint/report folder
            for a dataset.
    """
    if not str(path).strip():
        raise ValueError(f"{option}: empty; give a folder (. for the current one)")
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{option} {out}: is a file; give a folder")
    if not out.exists():
        _nearest_folder(out, option)
    _refuse_inside(out, option, inputs, self_too=not dataset)
    if dataset and out.is_dir():
        found = [m for m in RESULT_MARKERS if (out / m).is_file()]
        if found:
            raise ValueError(f"{option} {out}: holds {found[0]} (a training run's or a "
                             "benchmark's folder); give another folder for the dataset")
    return out


def png_path(path: str | Path, option: str = "--out",
             inputs: tuple[tuple[str, str | Path], ...] = ()) -> Path:
    """``path`` as a :class:`Path` if it names a ``.png`` file (the renderers write PNG).

    Raises:
        ValueError: another suffix (a ``.jpg`` name would hold PNG bytes), naming the fix.
    """
    out = Path(path)
    if out.suffix.lower() != ".png":
        raise ValueError(f"{option} {out}: the picture is a PNG; give a name ending in .png")
    if out.is_dir():  # before any work, not when the picture is written
        raise ValueError(f"{option} {out}: is a directory; give a file name ending in .png")
    _writable(out, option)
    _refuse_inside(out, option, inputs, self_too=False)
    return out


def _nearest_folder(out: Path, option: str) -> Path:
    """The nearest existing folder above ``out`` (where its folders would be made).

    Raises:
        ValueError: that path is a file, not a folder (naming ``option``)."""
    parent = out.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{option} {out}: cannot create its folder ({parent} is a file)")
    return parent


def _writable(out: Path, option: str) -> None:
    """A one-line ValueError when no file ``out`` can be made: its nearest existing
    folder is a file, is not writable, or refuses a new file (a probe made there and
    removed at once: root's access() says yes in /proc or on a read-only mount)."""
    parent = _nearest_folder(out, option)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {out}: {parent} is not writable; give a path you can "
                         "write to")
    if parent == out.parent:  # access() says yes to root in /proc or a read-only mount
        try:
            fd, probe = tempfile.mkstemp(dir=parent, prefix=f".{out.name}.", suffix=".probe")
        except OSError as exc:
            raise ValueError(f"{option} {out}: cannot create a file in {parent} "
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
    _writable(out, option)
    _refuse_inside(out, option, inputs, self_too=False)
    if out.is_file():
        with open(out, "rb") as fh:
            head = fh.read(4096)
        if b"\0" in head:  # a report replaces a report, never a binary file
            raise ValueError(f"{option} {out}: exists and is not a text file; give a new "
                             "file name")
    return out

