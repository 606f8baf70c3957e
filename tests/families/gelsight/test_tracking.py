"""Marker detection, tracking and the importer on synthetic marker videos."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slipkit.errors import SourceFormatError
from slipkit.families.gelsight.importer import read_gelsight
from slipkit.families.gelsight.tracking import detect_markers, marker_pitch, track_video

from .conftest import PITCH, draw, grid, sliding, write_video


def test_detects_every_marker_of_the_grid_at_its_centre() -> None:
    import cv2

    found = detect_markers(cv2.cvtColor(draw(grid()), cv2.COLOR_BGR2GRAY))
    assert len(found) == len(grid())
    d = np.linalg.norm(found[:, None] - grid()[None], axis=-1).min(axis=1)
    assert d.max() < 0.5
    assert marker_pitch(found) == pytest.approx(PITCH, abs=0.5)


def test_tracks_a_sliding_grid_without_losing_or_swapping_pins(tmp_path: Path) -> None:
    video = write_video(tmp_path / "camera_0.avi", sliding(20, speed=3.0))
    tr = track_video(video, n_pins=20)
    shift = tr.positions[-1] - tr.positions[0]
    assert np.allclose(shift[:, 0], 3.0 * 19, atol=1.0)
    assert np.allclose(shift[:, 1], 0.0, atol=1.0)
    assert tr.summary()["matched_mean"] == 1.0


def test_importer_reads_labels_groups_and_pin_streams(trials_folder: Path) -> None:
    ds = read_gelsight(trials_folder, n_pins=12)
    assert ds.sensor == "gelsight"
    assert sorted(ds.streams) == ["camera_0", "camera_2", "fingertips"]
    trials = ds.trials.set_index("trial_id")
    assert trials.loc["obj_a/exp_num_1", "slipped"] == 1.0
    assert trials.loc["obj_b/exp_num_1", "slipped"] == 0.0
    assert ds.groups == ("object",)
    trial = ds.trial("obj_a/exp_num_1")
    x = trial.streams["camera_0"][[f"x_{i}" for i in range(12)]].to_numpy()
    assert np.allclose(x[-1] - x[0], 0.8 * 11, atol=1.0)
    both = trial.streams["fingertips"]
    assert len(both) == min(len(trial.streams[c]) for c in ("camera_0", "camera_2"))
    np.testing.assert_array_equal(
        both[[f"camera_0_x_{i}" for i in range(12)]].to_numpy(), x[: len(both)]
    )
    assert ds.provenance["tracking"]["camera_0"]["matched_mean"] == 1.0


def test_missing_video_is_one_line_naming_the_file(trials_folder: Path) -> None:
    (trials_folder / "obj_b" / "exp_num_1" / "camera_2.avi").unlink()
    with pytest.raises(
        SourceFormatError, match=r"obj_b/exp_num_1/camera_2\.avi: missing video"
    ):
        read_gelsight(trials_folder)


def test_unreadable_video_names_the_file_and_frame(trials_folder: Path) -> None:
    bad = trials_folder / "obj_a" / "exp_num_1" / "camera_0.avi"
    bad.write_bytes(b"not a video")
    with pytest.raises(SourceFormatError, match=r"camera_0\.avi: .*frame 0"):
        read_gelsight(trials_folder)
