"""The shared real KITTI sample for the point-cloud tests (skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest
from shared_data import SHARED_DATA

SHARED = SHARED_DATA / "kitti-tracking"


@pytest.fixture(scope="session")
def real_root() -> Path:
    """The shared real sample (sequence 0003, frames 0-39), or skip."""
    if not (SHARED / "training" / "velodyne" / "0003").is_dir():
        pytest.skip(f"real KITTI sample absent ({SHARED.resolve()}); set DSTENV_SHARED_DATA "
                    "to a folder holding kitti-tracking/ (README, Set-up)")
    return SHARED
