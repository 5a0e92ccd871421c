"""Where the shared real data lie: ``../shared/data`` next to the repository, or
``$DSTENV_SHARED_DATA`` (a checkout elsewhere, e.g. a git worktree). Tests that read
them skip cleanly when the folder is absent."""

from __future__ import annotations

import os
from pathlib import Path

#: the folder holding ``kitti-tracking/`` and ``osm/``
SHARED_DATA = Path(os.environ.get(
    "DSTENV_SHARED_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "data"))
