"""The nested group-CV report on synthetic pin trials: steady drift (slip) against shakes."""

from __future__ import annotations

import numpy as np

from slipkit.families.gelsight.detectors import (
    ClipLengthControl,
    MajorityControl,
    PinMotionDetector,
)
from slipkit.families.gelsight.report import Candidate, evaluate


def _trial(rng: np.random.Generator, slip: bool, n: int) -> dict[str, np.ndarray]:
    xs, ys = np.meshgrid(np.arange(5) * 30.0, np.arange(5) * 30.0)
    p = np.column_stack([xs.ravel(), ys.ravel()])
    t = np.arange(n)[:, None]
    # slip: the field creeps steadily after frame 30; wiggle: it shakes and returns
    move = 0.4 * np.clip(t - 30, 0, None) if slip else 4.0 * np.sin(t / 2.0)
    noise = rng.normal(0, 0.05, (n, len(p)))
    x, y = p[:, 0] + move + noise, p[:, 1] + noise
    return {"camera_0": np.concatenate([x, y], axis=1)}


def _data(lengths: dict[bool, int]) -> tuple[list, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    trials, y, g = [], [], []
    for obj in range(6):
        for slip in (True, False, True, False):
            trials.append(_trial(rng, slip, lengths[slip]))
            y.append(int(slip))
            g.append(f"o{obj}")
    return trials, np.array(y), np.array(g)


def test_steady_drift_is_found_on_unseen_objects_and_the_controls_score_as_expected() -> (
    None
):
    trials, y, g = _data({True: 80, False: 80})
    steady = Candidate(
        "steady", (("w25", lambda: PinMotionDetector(quantity="steady", window=25)),)
    )
    r = evaluate(steady, trials, y, g, seed=0, outer=3, inner=2)
    assert r["balanced_accuracy"] == 1.0
    assert r["first_alarm_frame_slip"] > 30  # not before the creep starts
    major = evaluate(
        Candidate("m", (("", MajorityControl),)), trials, y, g, seed=0, outer=3, inner=2
    )
    assert major["balanced_accuracy"] == 0.5


def test_the_clip_length_control_reads_what_a_streaming_detector_must_not() -> None:
    trials, y, g = _data({True: 60, False: 120})
    r = evaluate(
        Candidate("len", (("", ClipLengthControl),)),
        trials,
        y,
        g,
        seed=1,
        outer=3,
        inner=2,
    )
    assert r["balanced_accuracy"] == 1.0
    # no trial runs the full length of the longest, the slip ones stop early: no
    # score on full-length clips alone (one class there)
    assert np.isnan(r["balanced_accuracy_full_length"])


def _score(factory, trials, y, g, seed: int = 0) -> dict:
    return evaluate(
        Candidate("c", (("", factory),)), trials, y, g, seed=seed, outer=3, inner=2
    )


def test_full_length_clips_are_scored_alone_where_clip_length_says_nothing() -> None:
    from slipkit.families.gelsight.report import full_length

    # half the slips stop early (the object dropped), the other half run the full
    # length beside the wiggles: on those, the clip-length control is at chance
    trials, y, g = _data({True: 120, False: 120})
    rng = np.random.default_rng(1)
    for i in np.flatnonzero(y == 1)[::2]:
        trials[i] = _trial(rng, True, 60)
    full = full_length(trials)
    assert full.sum() == len(y) - (y == 1).sum() // 2
    length = _score(ClipLengthControl, trials, y, g)
    assert length["balanced_accuracy"] == 0.75
    assert length["balanced_accuracy_full_length"] == 0.5
    steady = _score(
        lambda: PinMotionDetector(quantity="steady", window=25), trials, y, g
    )
    assert steady["balanced_accuracy_full_length"] == 1.0


def test_learned_detectors_score_frames_after_arming_and_separate_drift_from_shakes() -> (
    None
):
    from slipkit.families.gelsight.detectors import (
        TacTipVelocityDetector,
        WindowModelDetector,
    )

    trials, y, g = _data({True: 80, False: 80})
    for make in (
        lambda: WindowModelDetector(C=1.0, window=25, arm=12),
        lambda: TacTipVelocityDetector(C=1.0, smooth=10, arm=12),
    ):
        det = make().fit(trials, y)
        s = det.frame_scores(trials[0])
        assert np.isnan(s[:12]).all()
        assert np.isfinite(s[30:]).all()
        r = evaluate(
            Candidate("d", (("", make),)), trials, y, g, seed=0, outer=3, inner=2
        )
        assert r["balanced_accuracy"] >= 0.75


def _field(n: int, scale: np.ndarray, shift: np.ndarray) -> dict[str, np.ndarray]:
    """A 5x5 pin grid (pitch 30 px) scaled about its centre by ``scale[t]`` and moved
    along x by ``shift[t]``."""
    xs, ys = np.meshgrid(np.arange(5) * 30.0, np.arange(5) * 30.0)
    p = np.column_stack([xs.ravel(), ys.ravel()])
    c = p.mean(axis=0)
    pts = c + (p - c)[None] * scale[:, None, None]
    pts[..., 0] += shift[:, None]
    return {"camera_0": np.concatenate([pts[..., 0], pts[..., 1]], axis=1)}


def test_divergence_per_path_ranks_a_spreading_field_above_a_larger_shake() -> None:
    t = np.arange(80.0)
    # spreading by 1.5 % over 2 s with no net motion, against a shake of 4 px that
    # also spreads and contracts the field by 3 %
    spread = _field(80, 1 + 0.0003 * np.clip(t - 20, 0, None), np.zeros(80))
    shake = _field(80, 1 + 0.03 * np.abs(np.sin(t / 3)), 4.0 * np.sin(t / 3))
    per_path = PinMotionDetector(quantity="divergence_per_path", window=50)
    plain = PinMotionDetector(quantity="divergence", window=50)
    assert per_path.trial_score(spread) > per_path.trial_score(shake)
    assert plain.trial_score(spread) < plain.trial_score(shake)


def test_one_split_scores_only_its_test_objects() -> None:
    from slipkit.families.gelsight.report import _score_folds

    trials, y, g = _data({True: 80, False: 80})
    tr = np.flatnonzero(np.isin(g, ["o0", "o1", "o2", "o3"]))
    te = np.flatnonzero(np.isin(g, ["o4", "o5"]))
    steady = Candidate(
        "steady", (("w25", lambda: PinMotionDetector(quantity="steady", window=25)),)
    )
    r = _score_folds(steady, trials, y, g, [(tr, te)], seed=0, inner=2)
    assert r["balanced_accuracy"] == 1.0
    assert r["chosen"] == ["w25"]
    # a detector that fires on every trial: recall 1 and every test wiggle alarmed
    always = Candidate("len", (("", ClipLengthControl),))
    short = [{"camera_0": t["camera_0"][:40]} for t in trials]
    r = _score_folds(always, short, y, g, [(tr, te)], seed=0, inner=2)
    assert r["balanced_accuracy"] == 0.5


def test_a_runs_own_test_trials_are_read_as_the_deployed_row(tmp_path) -> None:
    import pandas as pd
    import pytest

    from slipkit.errors import SlipkitError
    from slipkit.families.gelsight.report import _run_trials

    pd.DataFrame(
        {
            "trial_id": ["a/1", "b/1", "b/2", "c/1"],
            "slipped": [True, True, False, False],
            "n_alarms": [1, 0, 1, 0],
            "first_alarm_s": [0.28, np.nan, 4.0, np.nan],
        }
    ).to_csv(tmp_path / "test_trials.csv", index=False)
    index = {"x/1": 0, "a/1": 1, "b/1": 2, "b/2": 3, "c/1": 4}
    y = np.array([0, 1, 1, 0, 0])
    full = np.array([True, False, True, True, True])
    r = _run_trials(tmp_path, index, y, full, 25.0)
    assert (r["slip_recall"], r["wiggle_false_alarm"]) == (0.5, 0.5)
    assert r["balanced_accuracy"] == 0.5
    assert r["balanced_accuracy_full_length"] == 0.25  # b/1 missed, b/2 fired
    assert r["first_alarm_frame_slip"] == 7
    index.pop("c/1")
    with pytest.raises(SlipkitError, match=r"test_trials\.csv: not the test trials"):
        _run_trials(tmp_path, index, y, full, 25.0)


def test_out_replaces_only_earlier_results_and_never_an_input(tmp_path) -> None:
    import json

    import pytest

    from slipkit.errors import SlipkitError
    from slipkit.families.gelsight.report import check_json_out, write_json_out

    data = tmp_path / "data.json"
    data.write_text("{}")
    inputs = {"dataset": str(data)}
    assert check_json_out(None, inputs) is None
    out = check_json_out(str(tmp_path / "r.json"), inputs)
    assert out is not None
    write_json_out(out, {"results": {"majority": {}}}, inputs)
    assert check_json_out(str(out), inputs) == out  # earlier results: replaced
    notes = tmp_path / "notes.json"
    notes.write_text(json.dumps({"mine": 1}))
    with pytest.raises(SlipkitError, match="not GelSight results"):
        check_json_out(str(notes), inputs)
    with pytest.raises(SlipkitError, match="--out"):
        check_json_out(str(data), inputs)
