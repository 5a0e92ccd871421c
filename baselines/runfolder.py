"""A training run's folder (``ppo_grid.py --out``): which files are the run's, and
claiming a folder for one run.

A run writes ``model.pt`` and its ``model.json`` sidecar, ``episodes.csv`` (the
learning curve), ``progress.csv`` (stable-baselines3's log) and, with
``--keep-checkpoints``, ``model_<steps>.pt`` / ``.json``. While it trains it holds
dstenv's folder lock (:func:`dstenv.data.lock.dataset_lock`), so a second run started
into the same folder (a ``for s ...; --out runs/x_s$s &`` loop with ``$s`` forgotten)
is refused at once instead of both writing there and one run being lost.

Outputs of the other scripts (``evaluate.py --csv``, ``tune_rule.py --out``) must never
replace a run's files (:func:`check_not_run_file`).
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator
from pathlib import Path

from dstenv.data.lock import LOCK_NAME, DatasetLocked, dataset_lock

__all__ = ["RUN_FILES", "run_files", "claim", "check_not_run_file"]

#: the files a run writes into ``--out`` (their presence: a run is there)
RUN_FILES = ("model.pt", "model.json", "episodes.csv", "progress.csv")
#: checkpoints kept by ``--keep-checkpoints``
KEPT = re.compile(r"model_\d+\.(pt|json)")


def run_files(folder: str | Path) -> list[str]:
    """Names of a run's files in ``folder`` (sorted; [] when none or no folder)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(p.name for p in folder.iterdir()
                  if p.name in RUN_FILES or KEPT.fullmatch(p.name))


@contextlib.contextmanager
def claim(folder: str | Path, flag: str = "--out") -> Iterator[Path]:
    """Hold ``folder`` for one training run (made if needed) for the block.

    Raises:
        ValueError: ``folder`` is a file, or holds a run's files (a finished or
            interrupted run, or kept checkpoints of one), naming the first.
        dstenv.data.lock.DatasetLocked: another run holds it now.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{flag} {folder}: is a file; give a folder for the run")
    _check_empty(folder, flag)  # before the lock: no folder is made for a refused run
    made = not folder.exists()
    try:
        with contextlib.ExitStack() as stack:
            try:
                stack.enter_context(dataset_lock(folder))
            except DatasetLocked:  # its text names generate's --force-unlock
                raise DatasetLocked(f"{flag} {folder}: another run holds it (its lock "
                                    f"{folder / LOCK_NAME}); wait for it, use another {flag}, "
                                    "or delete that lock file if its process is gone") from None
            _check_empty(folder, flag)  # again: a run may have finished there meanwhile
            yield folder
    except BaseException:
        if made:  # a run that failed before writing anything leaves no empty folder
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


def _check_empty(folder: Path, flag: str) -> None:
    taken = run_files(folder)
    if taken:  # a finished or interrupted run would be overwritten, or mixed with this one
        raise ValueError(f"{flag} {folder}: holds a training run ({taken[0]}"
                         + (f" and {len(taken) - 1} more" if len(taken) > 1 else "")
                         + "); choose another --out, or remove all of them to start over")


def check_not_run_file(path: str | Path, flag: str) -> None:
    """Refuse an output ``path`` that is one of a run's files, or its lock, in a folder
    that holds a run (``--csv runs/x/model.json`` replaced the sidecar and made the
    checkpoint unusable; ``--csv runs/x/episodes.csv`` the learning curve).

    Raises:
        ValueError: one line naming ``flag``, the path and the fix.
    """
    path = Path(path)
    name = path.name
    # a run is there when its checkpoint or lock is (an evaluation CSV of its own called
    # episodes.csv in another folder may be replaced)
    run_here = (path.parent / LOCK_NAME).exists() or any(
        n.startswith("model") for n in run_files(path.parent))
    if (name in RUN_FILES or KEPT.fullmatch(name) or name == LOCK_NAME) and run_here:
        raise ValueError(f"{flag} {path}: is a file of the training run in {path.parent}; "
                         "give another file name")
