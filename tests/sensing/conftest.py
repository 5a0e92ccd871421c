"""The shared real KITTI sample for the point-cloud tests (skipped when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# ../shared/data next to the repository, or $DSTENV_SHARED_DATA (a worktree elsewhere)
_DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
SHARED = Path(os.environ.get("DSTENV_SHARED_DATA", _DATA)) / "kitti-tracking"


@pytest.fixture(scope="session")
def real_root() -> Path:
    """The shared real sample (sequence 0003, frames 0-39), or skip."""
    if not (SHARED / "training" / "velodyne" / "0003").is_dir():
        pytest.skip(f"real KITTI sample absent ({SHARED.resolve()}); see shared/data/README.md")
    return SHARED
