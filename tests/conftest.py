"""Shared fixtures."""
from __future__ import annotations

from pathlib import Path

import pytest

#: the real clips, beside the checkout (never copied into the repository)
CLIPS_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "clips"


@pytest.fixture(scope="session")
def clips_dir() -> Path:
    """``../shared/data/clips`` beside the checkout; skips the test when it is absent."""
    if not CLIPS_DIR.is_dir():
        pytest.skip(f"real clips not found at {CLIPS_DIR} (they live beside the checkout, not in it)")
    return CLIPS_DIR
