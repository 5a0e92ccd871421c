"""Shard tasks on local worker processes (``dstenv generate --workers K``; the Ray twin
is :mod:`dstenv.data.ray_backend`).

Workers are spawned (``multiprocessing``'s "spawn" context), each with one thread per
numerical library, and die with the parent process; each task
writes its shard atomically (:func:`dstenv.data.generate.write_shard`), and frames done
are reported through a queue to the progress bar.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import queue as queue_mod
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dstenv.data.lifeline import die_with_parent
from dstenv.data.shards import partial_path

if TYPE_CHECKING:
    from dstenv.data.generate import ShardTask

__all__ = ["run_pool"]

_QUEUE: Any = None


def _init_worker(q: Any, parent: int) -> None:
    global _QUEUE
    die_with_parent(parent)  # a killed `dstenv generate` must not leave workers writing shards
    _QUEUE = q


def _worker_task(task: ShardTask, out: str) -> dict[str, Any]:
    from dstenv.data.generate import write_shard

    return write_shard(task, out, progress=_QUEUE.put if _QUEUE is not None else None)


#: thread pools of numerical libraries, one thread per worker process: K workers on K
#: cores must not each start K threads (unless the user set these variables)
_ONE_THREAD = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
               "MKL_NUM_THREADS")


def run_pool(todo: list[ShardTask], out: Path, workers: int, update: Callable[[int], None]
             ) -> dict[str, dict[str, Any]]:
    """Run the shard tasks ``todo`` on ``workers`` spawned processes writing into
    ``out``; ``update(n)`` is told of every ``n`` frames done. Returns ``{file: manifest
    entry}``. On any error or interrupt the workers are stopped and their unfinished
    files removed."""
    saved = {k: os.environ.get(k) for k in _ONE_THREAD}
    os.environ.update({k: "1" for k, v in saved.items() if v is None})
    try:  # spawned workers inherit the environment when they start
        return _run_pool_env(todo, out, workers, update)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)


def _run_pool_env(todo: list[ShardTask], out: Path, workers: int,
                  update: Callable[[int], None]) -> dict[str, dict[str, Any]]:
    ctx = multiprocessing.get_context("spawn")
    q = ctx.Queue()
    results: dict[str, dict[str, Any]] = {}

    def drain() -> None:
        n = 0
        try:
            while True:
                n += q.get_nowait()
        except queue_mod.Empty:
            pass
        if n:
            update(n)

    try:
        with cf.ProcessPoolExecutor(min(workers, len(todo)), mp_context=ctx,
                                    initializer=_init_worker, initargs=(q, os.getpid())) as ex:
            pending = {ex.submit(_worker_task, t, str(out)): t for t in todo}
            try:
                while pending:
                    finished, _ = cf.wait(pending, timeout=0.25, return_when=cf.FIRST_COMPLETED)
                    drain()
                    for fut in finished:
                        task = pending.pop(fut)
                        results[task.file] = fut.result()
            except BaseException:
                # stop the shards still running now rather than finishing them; the pool's
                # manager thread then fails the pending futures itself (cancelling them
                # here first made it raise InvalidStateError, a traceback on Ctrl-C)
                for proc in list(getattr(ex, "_processes", {}).values()):
                    proc.terminate()
                raise
    except BaseException:
        for task in todo:  # workers are gone: their unfinished files are garbage
            partial_path(out / task.file).unlink(missing_ok=True)
        raise
    drain()
    return results
