"""Time: duplicate timestamps (dt = 0), non-monotonic time, gaps and jitter in datasets and features."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tests.strategies import make_dataset

from slipkit._files import sha256_file
from slipkit.data import Trial
from slipkit.data.io import load_dataset, save_dataset
from slipkit.errors import DatasetError
from slipkit.families.tactip.features import trial_features
from slipkit.families.tactip.physics import pin_channels
from slipkit.features.pins import onset_velocity_index


def _rewrite_force(path: Path, edit: object) -> None:
    """Edit streams/force.parquet and fix its checksum, so only the content check can fail."""
    rel = "streams/force.parquet"
    df = pd.read_parquet(path / rel)
    edit(df)  # type: ignore[operator]
    df.to_parquet(path / rel, index=False)
    manifest = json.loads((path / "manifest.json").read_text())
    manifest["files"][rel] = sha256_file(path / rel)
    (path / "manifest.json").write_text(json.dumps(manifest))


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    return save_dataset(make_dataset(n_trials=2, n_frames=50), tmp_path / "ds")


def test_duplicate_timestamps_are_kept_as_recorded(saved: Path) -> None:
    """dt = 0 inside a trial is accepted (non-decreasing time) and loads back unchanged."""

    def dup(df: pd.DataFrame) -> None:
        df.loc[6, "t"] = df.loc[5, "t"]

    _rewrite_force(saved, dup)
    table = load_dataset(saved).stream("force")
    assert table.loc[5, "t"] == table.loc[6, "t"]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_time_is_named_with_row_and_trial(saved: Path, bad: float) -> None:
    """A NaN or infinite timestamp is refused naming the file, column, row and trial."""

    def edit(df: pd.DataFrame) -> None:
        df.loc[7, "t"] = bad

    _rewrite_force(saved, edit)
    with pytest.raises(
        DatasetError, match=r"column 't' is not finite at row 7 \(trial 'trial-000'\)"
    ) as info:
        load_dataset(saved)
    assert "force.parquet" in str(info.value)


def test_time_going_backwards_in_memory_is_refused() -> None:
    """A Trial whose time goes back is refused when the dataset is assembled, naming the trial."""
    ds = make_dataset(n_trials=1, n_frames=20, with_events=False)
    trial = next(iter(ds))
    force = trial.streams["force"].copy()
    force.loc[10, "t"] = 0.0
    bad = Trial(trial.trial_id, {"force": force}, labels=trial.labels, meta=trial.meta)
    with pytest.raises(
        DatasetError, match=r"'t' decreases at row 10 \(trial 'trial-000'\)"
    ):
        type(ds).from_trials(
            [bad],
            sensor=ds.sensor,
            streams={"force": ds.streams["force"]},
            labels=ds.labels,
            groups=ds.groups,
            provenance={},
        )


# -- features read frames, not clocks --------------------------------------------------
def _pin_trial(t: np.ndarray, onset: float, n_pins: int = 5, seed: int = 0) -> Trial:
    rng = np.random.default_rng(seed)
    xy = np.cumsum(rng.normal(scale=0.05, size=(len(t), 2 * n_pins)), axis=0)
    table = pd.DataFrame(xy, columns=list(pin_channels(n_pins)))
    table.insert(0, "t", t)
    return Trial("pins-000", {"pins": table}, labels={"slip_onset_s": onset})


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(
        st.sampled_from([0.0, 1.0, 1.0, 1.0, 0.7, 1.3, 2.0, 5.0]),
        min_size=2,
        max_size=40,
    ),
    onset_frac=st.floats(-0.2, 1.2),
)
def test_pin_features_are_finite_under_duplicates_gaps_and_jitter(
    steps: list[float], onset_frac: float
) -> None:
    """Frame intervals of 0, jittered, or several periods: finite features, one row per frame pair, a valid onset row."""
    t = np.concatenate([[0.0], np.cumsum(steps)]) / 120.0
    onset = float(t[0] + onset_frac * (t[-1] - t[0]))
    X, y, times, k = trial_features(_pin_trial(t, onset))
    assert (len(t) - 1, len(t) - 1) == (len(X), len(y))
    assert np.isfinite(X).all()
    np.testing.assert_array_equal(t[1:], times)
    if onset > t[-1]:
        assert k is None
    else:
        assert k is not None
        assert 0 <= k < len(t) - 1
        # The onset lies in the velocity frame's interval (t_k, t_{k+1}] (or before frame 0).
        assert onset <= t[k + 1]
        assert k == 0 or t[k] < onset


def test_onset_on_a_duplicated_timestamp_goes_to_the_first_interval_ending_there() -> (
    None
):
    """With t = [0, 1, 1, 2], an onset at 1 s belongs to velocity frame 0, the first interval ending at 1 s."""
    assert 0 == onset_velocity_index(np.array([0.0, 1.0, 1.0, 2.0]), 1.0)


def test_one_frame_pin_trial_is_refused_naming_the_trial() -> None:
    """A TacTip trial of a single frame has no velocity: a clear error naming the trial, not an empty array."""
    with pytest.raises(
        ValueError, match=r"trial 'pins-000': 1 frames; velocities need >= 2"
    ):
        trial_features(_pin_trial(np.array([0.0]), 0.0))
