"""Shard tasks as Ray tasks (``dstenv generate --ray [ADDRESS]``; extra ``dstenv[ray]``).

Each Ray task simulates one shard into a local temporary directory on whichever node
runs it and returns the file's bytes; the driver writes them under the final name
atomically and checks their SHA-256. Nodes therefore need no shared file system,
only the same dstenv installed (or a ``runtime_env``). With ``ADDRESS`` omitted a
local Ray is started with ``--workers`` CPUs.
"""

from __future__ import annotations

import hashlib
import importlib.util
import socket
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from dstenv.io import atomic_write_bytes

__all__ = ["check_ray_address", "run_ray", "shard_bytes"]

NO_RAY = "--ray needs Ray: pip install -e '.[ray]' in the dstenv checkout"


def shard_bytes(task: Any) -> tuple[bytes, dict[str, Any]]:
    """Run one :class:`~dstenv.data.generate.ShardTask` in a scratch directory.

    Returns:
        the shard file's bytes and its manifest entry.
    """
    from dstenv.data.generate import write_shard

    with tempfile.TemporaryDirectory(prefix="dstenv-shard-") as tmp:
        entry = write_shard(task, tmp)
        return (Path(tmp) / task.file).read_bytes(), entry


def ray_installed() -> bool:
    """Ray can be imported here (without importing it)."""
    return importlib.util.find_spec("ray") is not None


def check_ray_address(address: str, timeout: float = 3.0) -> None:
    """Before any folder or task exists: a cluster address names a head that answers.

    ``ray.init`` on an address where nothing listens waited minutes, printing Ray's
    C++ warnings (and an address other than the one given), and ignored SIGTERM.
    ``"local"`` and ``"auto"`` are Ray's to resolve; ``HOST:PORT`` and
    ``ray://HOST:PORT`` must parse and accept a TCP connection within ``timeout`` [s].

    Raises:
        GenerateError: one line naming ``--ray``, the address and the fix.
    """
    from dstenv.data.generate import GenerateError

    if not ray_installed():  # (it was found after the folder and a progress bar)
        raise GenerateError(NO_RAY)
    if address in ("local", "auto"):
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise GenerateError(f"--ray {address!r}: expected HOST:PORT of a head started with "
                            "'ray start --head' (e.g. 127.0.0.1:6379), ray://HOST:PORT, auto, "
                            "or no address for a local Ray")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as exc:
        raise GenerateError(f"--ray {address}: no Ray head answers at {host}:{port} "
                            f"({exc.strerror or exc}); start one with 'ray start --head "
                            f"--port {port}' or check the address") from None


def run_ray(todo: list[Any], out: Path, address: str, workers: int,
            update: Callable[[int], None]) -> dict[str, dict[str, Any]]:
    """Run shard tasks on Ray and write their files under ``out``.

    Args:
        todo: :class:`~dstenv.data.generate.ShardTask` objects.
        out: output directory on the driver.
        address: ``"local"`` (start a local Ray with ``workers`` CPUs) or a cluster
            address passed to ``ray.init`` (``"auto"``, ``"ray://host:10001"``).
        workers: CPUs of a local Ray (ignored for a cluster).
        update: progress callback, called with the frames of each finished shard.

    Returns:
        ``{task.file: manifest entry}``.
    """
    try:
        import ray
    except ImportError:
        from dstenv.data.generate import GenerateError

        raise GenerateError(NO_RAY) from None
    if not todo:
        return {}
    started = not ray.is_initialized()
    if started:
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": True}
        if address == "local":
            ray.init(num_cpus=workers, **kwargs)
        else:
            ray.init(address=address, **kwargs)
    try:
        remote = ray.remote(num_cpus=1, max_retries=2)(shard_bytes)
        pending = {remote.remote(t): t for t in todo}
        results: dict[str, dict[str, Any]] = {}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            task = pending.pop(ready[0])
            data, entry = ray.get(ready[0])
            if hashlib.sha256(data).hexdigest() != entry["sha256"]:
                raise OSError(f"{task.file}: bytes from Ray do not match their SHA-256")
            atomic_write_bytes(out / task.file, data)
            results[task.file] = entry
            update(task.frames)
        return results
    finally:
        if started:
            ray.shutdown()
