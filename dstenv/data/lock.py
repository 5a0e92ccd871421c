"""An advisory lock on a dataset folder: one writer at a time.

HDF5's own file locking is off on many shared file systems (NFS, Lustre), and two
``dstenv generate`` runs into one folder would then mix shards of two settings.
:func:`dataset_lock` creates ``DIR/.dstenv.lock`` exclusively (``O_CREAT | O_EXCL``,
which NFS honours) holding the owner's host and pid, and also ``flock``s it where
the system supports that. A lock left by a process that no longer runs on this host
is taken over; one held by another host is reported with its owner, and
``--force-unlock`` is the documented way out.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
from collections.abc import Iterator
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: the O_EXCL lock file alone
    fcntl = None  # type: ignore[assignment]

__all__ = ["LOCK_NAME", "DatasetLocked", "dataset_lock", "writer_of"]

LOCK_NAME = ".dstenv.lock"


class DatasetLocked(RuntimeError):
    """Another process writes into the same dataset folder."""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _owner(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


@contextlib.contextmanager
def dataset_lock(folder: str | Path, force: bool = False) -> Iterator[Path]:
    """Hold ``folder/.dstenv.lock`` for the duration of the block.

    Args:
        folder: the dataset folder (created if needed).
        force: take the lock even if another owner holds it (after a crash on
            another host).

    Raises:
        DatasetLocked: another live process (here, or on another host) holds it;
            the message names the owner and the fix.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    me = {"host": socket.gethostname(), "pid": os.getpid()}
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            break
        except FileExistsError:
            owner = _owner(path)
            here = owner.get("host") == me["host"]
            stale = here and not _alive(int(owner.get("pid", -1)))
            if force and here and not stale:  # a live writer here: forcing would mix shards
                raise DatasetLocked(
                    f"{folder} is being written by pid {owner.get('pid')} on this host, which "
                    "is still running; --force-unlock is for a lock left by a process that "
                    "is gone (stop that run first)") from None
            if not (stale or force):
                who = f"pid {owner.get('pid', '?')} on {owner.get('host', '?')}"
                raise DatasetLocked(
                    f"{folder} is being written by {who} ({path}); wait for it, use another "
                    "--out, or pass --force-unlock if that process is gone") from None
            path.unlink(missing_ok=True)
    else:  # pragma: no cover - lost a race twice
        raise DatasetLocked(f"{folder}: could not take {path}; another run started just now")
    try:
        if fcntl is not None:  # flock: extra safety where the file system supports it
            with contextlib.suppress(OSError):
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.write(fd, json.dumps(me).encode())
        os.fsync(fd)
        yield path
    finally:
        os.close(fd)
        if _owner(path).get("pid") == me["pid"]:
            path.unlink(missing_ok=True)


def writer_of(folder: str | Path) -> str | None:
    """Who is writing into ``folder`` now: ``"pid N on HOST"`` when its lock is held by a
    live process here or by any process on another host (it cannot be checked from
    here); ``None`` when there is no lock, or its process is gone."""
    path = Path(folder) / LOCK_NAME
    if not path.is_file():
        return None
    owner = _owner(path)
    here = owner.get("host") == socket.gethostname()
    if here and not _alive(int(owner.get("pid", -1))):
        return None
    return f"pid {owner.get('pid', '?')} on {owner.get('host', '?')}"

