"""An advisory lock on a dataset folder: one writer at a time.

HDF5's own file locking is off on many shared file systems (NFS, Lustre), and two
``dstenv generate`` runs into one folder would then mix shards of two settings.
:func:`dataset_lock` creates ``DIR/.dstenv.lock`` exclusively (``O_CREAT | O_EXCL``,
which NFS honours) holding the owner's host, pid and the process's start time (so a
pid reused by another process does not hold it), and also ``flock``s it where the
system supports that. A lock left by a process that no longer runs on this host, or
one that never got an owner (a start that failed, e.g. on a full disk), is taken over,
one process at a time; one held by another host is reported with its owner, and
``--force-unlock`` is the documented way out.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from collections.abc import Iterator
from pathlib import Path

from dstenv.config import CLIError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: the O_EXCL lock file alone
    fcntl = None  # type: ignore[assignment]

__all__ = ["LOCK_NAME", "DatasetLocked", "dataset_lock", "writer_of"]

LOCK_NAME = ".dstenv.lock"


class DatasetLocked(CLIError, RuntimeError):
    """Another process writes into the same dataset folder."""


#: [s] a lock file still without an owner after this long was left by a failed start
_UNOWNED_STALE_S = 30.0


def _stat(pid: int) -> list[str]:
    """Fields of ``/proc/PID/stat`` after the command name (state first); [] where unknown."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return []


def _started(pid: int) -> str | None:
    """When process ``pid`` started (Linux: /proc's start time in clock ticks), so a pid
    reused by another process is not taken for the lock's owner; None where unknown."""
    stat = _stat(pid)
    return stat[19] if len(stat) > 19 else None


def _alive(owner: dict) -> bool:
    """Whether the lock's owner (on this host) still runs: its pid, started when it was."""
    pid = int(owner.get("pid", -1))
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return pid > 0
    if _stat(pid)[:1] in (["Z"], ["X"]):  # killed, not yet reaped by its parent: gone
        return False
    start = owner.get("started")
    return start is None or _started(pid) in (None, start)


def _owner(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _stale(path: Path, owner: dict, me: dict) -> bool:
    """A lock nobody holds any more: its owner here is gone, or it never got an owner."""
    if not owner:  # created, never written (a failed start), or being written right now
        try:
            return time.time() - path.stat().st_mtime > _UNOWNED_STALE_S
        except OSError:
            return True
    return owner.get("host") == me["host"] and not _alive(owner)


@contextlib.contextmanager
def _takeover(folder: Path) -> Iterator[None]:
    """One process at a time removes a stale lock (two that both saw it stale would
    otherwise each remove the other's new lock)."""
    guard = folder / (LOCK_NAME + ".takeover")
    for _ in range(200):
        try:
            os.close(os.open(guard, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
            break
        except FileExistsError:
            with contextlib.suppress(OSError):  # a takeover that died half-way
                if time.time() - guard.stat().st_mtime > _UNOWNED_STALE_S:
                    guard.unlink()
            time.sleep(0.01)
    else:  # pragma: no cover - a takeover longer than 2 s
        raise DatasetLocked(f"{folder}: another run is taking over its lock; try again")
    try:
        yield
    finally:
        guard.unlink(missing_ok=True)


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
    me = {"host": socket.gethostname(), "pid": os.getpid(), "started": _started(os.getpid())}
    for _ in range(3):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            break
        except FileExistsError:
            owner = _owner(path)
            if not owner and not path.exists():  # released since our create: try again
                continue  # (judged stale, the next one's new, still empty lock was removed)
            stale = _stale(path, owner, me)
            live_here = owner.get("host") == me["host"] and not stale
            if force and live_here:  # a live writer here: forcing would mix shards
                raise DatasetLocked(
                    f"{folder} is being written by pid {owner.get('pid')} on this host, which "
                    "is still running; --force-unlock is for a lock left by a process that "
                    "is gone (stop that run first)") from None
            if not (stale or force):
                who = (f"pid {owner.get('pid', '?')} on {owner.get('host', '?')}" if owner
                       else "a run that is starting")
                raise DatasetLocked(
                    f"{folder} is being written by {who} ({path}); wait for it, use another "
                    "--out, or pass --force-unlock if that process is gone") from None
            with _takeover(folder):
                now = _owner(path)  # still the lock judged stale, not a new one (an
                if now == owner and (owner or _stale(path, now, me)):  # empty one: by age)
                    path.unlink(missing_ok=True)
    else:  # pragma: no cover - lost a race three times
        raise DatasetLocked(f"{folder}: could not take {path}; another run started just now")
    try:
        if fcntl is not None:  # flock: extra safety where the file system supports it
            with contextlib.suppress(OSError):
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.write(fd, json.dumps(me).encode())
        os.fsync(fd)
    except BaseException:  # e.g. a full disk: leave no lock without an owner behind
        os.close(fd)
        path.unlink(missing_ok=True)
        raise
    try:
        yield path
    finally:
        os.close(fd)
        if _owner(path).get("pid") == me["pid"]:
            # a folder made read-only meanwhile: the lock stays (stale once this process
            # is gone) rather than its PermissionError hiding the run's own error
            with contextlib.suppress(OSError):
                path.unlink(missing_ok=True)


def writer_of(folder: str | Path) -> str | None:
    """Who is writing into ``folder`` now: ``"pid N on HOST"`` when its lock is held by a
    live process here or by any process on another host (it cannot be checked from
    here); ``None`` when there is no lock, its process is gone, or it never got an owner
    (a start that failed more than :data:`_UNOWNED_STALE_S` ago)."""
    path = Path(folder) / LOCK_NAME
    if not path.is_file():
        return None
    owner = _owner(path)
    if _stale(path, owner, {"host": socket.gethostname()}):
        return None
    return (f"pid {owner.get('pid', '?')} on {owner.get('host', '?')}" if owner
            else "a run that is starting")

