"""Worker processes that die with their parent, and a parent that cleans up on SIGTERM.

``kill -9`` of ``dstenv generate`` (or SLURM / ``docker stop`` sending SIGTERM, then
SIGKILL) must not leave workers running and writing into the output folder. Two
mechanisms, because neither alone covers every case:

* :func:`die_with_parent` (called in each worker at start): on Linux the kernel's
  parent-death signal (``prctl(PR_SET_PDEATHSIG, SIGKILL)``) kills the worker the
  moment its parent dies, even by SIGKILL; everywhere, a daemon thread also polls
  the parent pid and exits the worker when it changes (the worker was re-parented).
* :func:`sigterm_as_interrupt` (around the parent's work): SIGTERM raises
  :class:`Terminated`, so the parent's ``finally`` blocks stop the workers and remove
  their partial files before it exits, exactly as on Ctrl-C.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator

__all__ = ["Terminated", "die_with_parent", "sigterm_as_interrupt"]

_PR_SET_PDEATHSIG = 1


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; handled like Ctrl-C (cleanup runs, exit status 143)."""


def die_with_parent(parent: int, poll: float = 0.2) -> None:
    """Make the calling process exit as soon as its parent process dies.

    Args:
        parent: the parent's pid, as the parent saw it (``os.getpid()`` there): read
            in the child it would already be 1 if the parent died during start-up.
        poll: [s] period of the portable parent-pid check.
    """
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(poll)
            if os.getppid() != parent:
                os._exit(1)  # no cleanup: the parent's files are not ours to finish

    threading.Thread(target=watch, name="dstenv-lifeline", daemon=True).start()


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (main thread only); one that
    landed where Python cannot raise it (numba code, a finaliser) is raised on leaving."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    hit: list[int] = []

    def handler(signum: int, frame: object) -> None:
        hit.append(signum)
        raise Terminated(f"terminated by signal {signum}")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    except SystemError:  # raised inside a compiled (numba) call: numba's wrapping of it
        if hit:
            raise Terminated(f"terminated by signal {hit[0]}") from None
        raise
    finally:
        signal.signal(signal.SIGTERM, previous)
    if hit:  # raised where Python only prints it (a __del__, a weakref callback)
        raise Terminated(f"terminated by signal {hit[0]}")
