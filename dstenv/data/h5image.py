"""An HDF5 file built in memory and written to disk in one go.

:class:`~dstenv.data.writer.ShardWriter` builds a shard with HDF5's ``core`` driver
(no backing store) and writes the finished file image to its ``.partial`` file with
plain ``os.write``: a full disk (or any other write error) is then an ordinary
``OSError`` raised by Python. Written by HDF5 itself, a failed flush left HDF5's
objects half closed, and freeing the shard's datasets afterwards crashed the process
with a segmentation fault (attack 17: ``dstenv generate`` on a full disk, 4 of 4
runs). The bytes are those HDF5 writes to a file (checked by the tests: the same
SHA-256 as a shard written through the ``sec2`` driver).

The ``.partial`` file is created and ``flock``-ed when the shard starts, so a second
writer of the same shard is refused at once, as HDF5's own file lock did.
"""

from __future__ import annotations

import contextlib
import errno
import os
from pathlib import Path

import h5py

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no lock
    fcntl = None  # type: ignore[assignment]

__all__ = ["create", "commit", "discard"]


def create(tmp_path: Path) -> tuple[h5py.File, int]:
    """Start a file: ``(the in-memory HDF5 file, the locked .partial file's descriptor)``.

    Raises:
        OSError: the ``.partial`` file cannot be made, or another writer holds it
            (``errno.EBUSY``).
    """
    fd = os.open(tmp_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        if fcntl is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise OSError(errno.EBUSY, "already open by another writer") from None
            except OSError:  # a file system without flock: the shard's name is the lock
                pass
            st = os.fstat(fd)  # locked, but renamed to the shard meanwhile: not ours
            if not os.path.exists(tmp_path) or os.stat(tmp_path).st_ino != st.st_ino:
                raise OSError(errno.EBUSY, "already open by another writer")
        os.ftruncate(fd, 0)
        # the name is HDF5's identity of an open file: a second writer of this path in
        # this process is refused ("already open") like one in another process
        f = h5py.File(str(tmp_path), "w", driver="core", backing_store=False,
                      track_order=False)
    except BaseException:
        os.close(fd)
        raise
    return f, fd


def commit(f: h5py.File, fd: int, tmp_path: Path, path: Path) -> None:
    """Write the finished file to ``tmp_path`` (through ``fd``), sync it and rename it to
    ``path``. ``f`` and ``fd`` are closed either way.

    Raises:
        OSError: a write error (a full disk): ``tmp_path`` is removed, ``path`` untouched.
    """
    try:
        f.flush()
        image = memoryview(f.id.get_file_image())
    finally:
        f.close()
    try:
        os.ftruncate(fd, 0)
        while image:
            image = image[os.write(fd, image):]
        os.fsync(fd)
        os.replace(tmp_path, path)  # renamed while still locked: no second writer can take
    except BaseException:  # the .partial name in between (attack 19)
        discard(None, fd, tmp_path)
        raise
    os.close(fd)


def discard(f: h5py.File | None, fd: int | None, tmp_path: Path) -> None:
    """Drop an unfinished file: close both (ignoring HDF5's errors after a failed
    write; ``fd`` None: ``f`` is HDF5's own file of ``tmp_path``) and remove
    ``tmp_path``."""
    if f is not None:
        with contextlib.suppress(OSError, RuntimeError, ValueError):
            f.close()
    if fd is not None:
        with contextlib.suppress(OSError):
            os.close(fd)
    Path(tmp_path).unlink(missing_ok=True)
