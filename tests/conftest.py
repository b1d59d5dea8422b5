"""Shared fixtures: analytic worlds, simple trajectories, the real-data folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REAL_DATA = Path(os.environ.get("SALO_REAL_DATA", REPO.parent / "shared" / "data" / "real"))


def require_real_data() -> Path:
    if not REAL_DATA.is_dir():
        pytest.skip(f"real data folder {REAL_DATA} not present (set SALO_REAL_DATA)")
    return REAL_DATA


@pytest.fixture
def real_data() -> Path:
    return require_real_data()
