"""Shared fixtures: where the real recordings are, and Hydra's global state."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path | None:
    """``$SLIPKIT_DATA`` if set, else ``../shared/data`` beside the checkout, if present."""
    env = os.environ.get("SLIPKIT_DATA")
    candidate = Path(env) if env else ROOT.parent / "shared" / "data"
    return candidate if candidate.is_dir() else None


@pytest.fixture
def shared_data() -> Path:
    """The real public recordings; the test is skipped cleanly when they are absent."""
    path = shared_data_dir()
    if path is None:
        pytest.skip(
            "real recordings not found (set SLIPKIT_DATA or place ../shared/data)"
        )
    return path


@pytest.fixture(autouse=True)
def _clear_hydra():
    """Tests that compose configs leave no global Hydra state behind."""
    yield
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
