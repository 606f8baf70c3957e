"""Tracking on a real GelSight video (skipped when the shared data folder is absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slipkit.families.gelsight.tracking import _read_gray, track_frames

pytestmark = pytest.mark.realdata


def test_tracks_the_first_seconds_of_a_real_trial(shared_data: Path) -> None:
    video = shared_data / "gelsight-slip/train/avocado_real/exp_num_1/camera_2.avi"
    if not video.is_file():
        pytest.skip("gelsight-slip not in the shared data")
    tr = track_frames(_read_gray(video)[:50], n_pins=30, where=str(video))
    s = tr.summary()
    assert s["markers_first_frame"] >= 40
    assert s["pins"] == 30
    assert s["matched_mean"] >= 0.95
    assert s["drift_px_median"] < 0.5
    assert 25 < tr.pitch_px < 40
    assert np.isfinite(tr.positions).all()
