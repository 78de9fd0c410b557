"""Shared fixtures: paths to ../shared (skipped cleanly when absent), seeded generators."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
TARGETS_DIR = SHARED / "data" / "targets"
MESH_NAMES = ["voyager", "orion", "aura", "eros", "comet67p"]


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def shared_targets() -> Path:
    """``../shared/data/targets`` or skip."""
    if not TARGETS_DIR.is_dir():
        pytest.skip("../shared/data/targets not present")
    return TARGETS_DIR
