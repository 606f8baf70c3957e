"""TacTip: the SVMs (frame task) and the pin-motion detector (stream task) ranked on one trial-event measure."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.compare.adapters import (
    frame_task_events,
    stream_task_events,
    trial_events,
)
from slipkit.compare.commands import run_comparison


def test_trial_outcomes_and_rates_of_a_hand_made_case() -> None:
    """On time (0-2 frames), early, late, missed, quiet and false alarm, and the two rates."""
    row, table = trial_events(
        ["a", "b", "c", "d", "e", "f"],
        [5, 5, 5, 5, None, None],
        [7, 4, 8, None, None, 3],
    )
    assert ["on_time", "early", "late", "missed", "quiet", "false_alarm"] == table[
        "outcome"
    ].tolist()
    assert {
        "on_time_rate": 2 / 6,
        "no_early_alarm_rate": 4 / 6,
        "late_slips": 1,
        "event_trials": 6,
    } == row


def test_frame_and_stream_conventions_give_the_same_frames() -> None:
    """One trial's alarm as a debounced velocity-frame table and as pin samples: same onset and alarm frame."""
    t = np.arange(12) / 60.0  # camera frames, s
    onset_s = 3.5 / 60.0  # between camera frames 3 and 4: velocity frame 3
    labels = np.where((np.arange(11) >= 3) & (np.arange(11) < 7), "slip", "static")
    pred = np.array(["static"] * 11, dtype=object)
    pred[[4, 5]] = "slip"  # the 2-frame rule fires at velocity frame 5
    frames = pd.DataFrame({"trial_id": "a", "t": t[1:], "label": labels, "pred": pred})
    _, from_frames = frame_task_events(frames, "slip", 2)
    fired = np.zeros(12, dtype=bool)
    fired[6:] = True  # sample 6 ends velocity frame 5
    _, from_stream = stream_task_events(t, fired, [(0, 12)], np.array([onset_s]), ["a"])
    assert from_frames.to_dict("list") == from_stream.to_dict("list")
    assert [3.0, 5.0, "on_time"] == from_stream.loc[
        0, ["onset_frame", "first_alarm_frame", "outcome"]
    ].tolist()


def test_both_tasks_rows_carry_the_event_score_on_the_same_trials(
    tmp_path: Path,
) -> None:
    """comparison=tactip: the SVM and the detector rows hold on_time_rate and the trial cost, over the same trials and onset frames."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="compare",
            overrides=[
                "comparison=tactip",
                f"out={tmp_path / 'c'}",
                "progress=false",
                "comparison.dataset.n_trials=4",
                "~comparison.estimators.svm_rbf_tuned",
                "~comparison.estimators.svm_linear",
                "cost.export=false",
            ],
        )
    (tmp_path / "c").mkdir()
    result = run_comparison(cfg, tmp_path / "c", progress=False)
    svm = result.evaluations["svm_rbf"].trial_events
    det = result.evaluations["alignment"].trial_events
    assert isinstance(svm, pd.DataFrame)
    assert isinstance(det, pd.DataFrame)
    assert ("cost", 2) == (result.table.attrs["primary"], len(det))
    assert svm[["trial_id", "onset_frame"]].to_dict("list") == det[
        ["trial_id", "onset_frame"]
    ].to_dict("list")
    rows = result.table.set_index("estimator")
    # both rows carry the trial events of their deployed operating point, on both test trials
    assert [2, 2] == rows.loc[["svm_rbf", "alignment"], "event_trials"].tolist()
    assert rows.loc[["svm_rbf", "alignment"], "cost"].notna().all()
    for name, events in (("svm_rbf", svm), ("alignment", det)):
        on_time = float(np.mean(events["outcome"].isin(["on_time", "quiet"])))
        early = float(np.mean(events["outcome"].isin(["early", "false_alarm"])))
        assert (on_time, 1.0 - early, len(events)) == (
            rows.loc[name, "on_time_rate"],
            rows.loc[name, "no_early_alarm_rate"],
            rows.loc[name, "event_trials"],
        )
