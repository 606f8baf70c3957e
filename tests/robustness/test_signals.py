"""Constant, flat and short signals through every analytic detector, batch and streaming."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from slipkit.errors import SlipkitError
from slipkit.families.biotac.detectors import ForceDerivative, PressureVibration
from slipkit.families.davis.polarity import DavisPolarity
from slipkit.families.fsr.touch_slip import FSRTouchSlip
from slipkit.families.sliptack.accel import DropAcceleration
from slipkit.families.sliptack.speed import (
    PAPER_F_MAX,
    StickSlipSpeed,
    dominant_frequency,
)
from slipkit.families.sliptack.torsion import TorsionalSlipDetector

RATE = 1000.0
#: Relative round-off a flat signal may leave in a band-pass score (of |level|).
FLAT_REL = 1e-12


def _detectors() -> list[Any]:
    return [
        FSRTouchSlip(threshold=1.0, polarity="falling"),
        PressureVibration(threshold=1.0),
        ForceDerivative(threshold=1.0),
        TorsionalSlipDetector(threshold=1.0),
    ]


def _ids(dets: list[Any]) -> list[str]:
    return [type(d).__name__ for d in dets]


def _batch_and_stream(det: Any, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    det.fit(X, np.zeros(len(X)))
    batch = det.decision_function(X)
    stream, _ = det.replay(X)
    return batch, stream


@pytest.mark.parametrize("det", _detectors(), ids=_ids(_detectors()))
@pytest.mark.parametrize("n", [1, 2, 3])
def test_few_sample_streams_only_warm_up(det: Any, n: int) -> None:
    """One to three samples: every detector, batch and stream alike, scores -inf (warm-up), no warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        batch, stream = _batch_and_stream(det, np.full((n, 1), 2.5))
    assert [-math.inf] * n == batch.tolist() == stream.tolist()


@pytest.mark.parametrize("det", _detectors(), ids=_ids(_detectors()))
@pytest.mark.parametrize("level", [0.0, 1e-12, 3000.0, -1e12, 1e12])
def test_flat_signals_never_fire_and_never_make_nan(det: Any, level: float) -> None:
    """A flat signal at any level (0, 1e-12 .. 1e12) scores no NaN, agrees batch/stream, and stays at round-off."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        batch, stream = _batch_and_stream(det, np.full((3000, 1), level))
    assert not np.isnan(batch).any()
    np.testing.assert_array_equal(np.isfinite(batch), np.isfinite(stream))
    finite = np.isfinite(batch)
    np.testing.assert_allclose(batch[finite], stream[finite], rtol=1e-9, atol=1e-300)
    # Scores are rates, band energies or ratios of them: a flat signal has none beyond
    # round-off of its level (the BioTac ratio is 0 / floor).
    assert FLAT_REL * max(1.0, abs(level)) >= np.max(batch[finite], initial=0.0)


def test_torsional_band_pass_ignores_a_resting_deflection_and_dropped_samples() -> None:
    """A nib resting at 3 mm with NaN dropouts has no 10 Hz band energy (no start-up or dropout ringing)."""
    x = np.full((2000, 1), 3.0)
    x[[0, 500, 501, 1500], 0] = np.nan
    det = TorsionalSlipDetector(threshold=0.01)
    batch, stream = _batch_and_stream(det, x)
    np.testing.assert_array_equal(batch, stream)
    assert 0 == int(det.predict(x).sum())
    assert FLAT_REL * 3.0 >= np.max(batch[np.isfinite(batch)])


# -- SlipTack: DFT shorter than the moving average, acceleration from one point ----------
@settings(max_examples=60, deadline=None)
@given(
    x=arrays(
        np.float64,
        st.integers(0, 299),
        elements=st.floats(-1e12, 1e12, allow_nan=False, allow_subnormal=False),
    )
)
def test_dft_on_fewer_samples_than_the_300_frame_average(x: np.ndarray) -> None:
    """Any window under 300 samples gives NaN or a frequency within eq. 7's range, without a warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f = dominant_frequency(x, RATE, detrend_frames=300)
    assert math.isnan(f) or 0.0 <= f <= max(PAPER_F_MAX)


@pytest.mark.parametrize("n", [60, 120, 200, 299])
def test_short_window_still_finds_a_clean_stick_slip_tone(n: int) -> None:
    """A 25 Hz tone in fewer samples than the moving average is found within one DFT bin."""
    t = np.arange(n) / RATE
    x = 2.0 + 0.1 * t + 0.05 * np.sin(2 * np.pi * 25.0 * t)
    f = dominant_frequency(x, RATE, detrend_frames=300, min_peak_ratio=0.5)
    assert abs(f - 25.0) <= RATE / n


@pytest.mark.parametrize("feature", ["deflection", "frequency_slope"])
def test_acceleration_fit_on_a_single_point_is_refused(feature: str) -> None:
    """One sample cannot calibrate eq. 4's line: a clear error naming the problem, not a NaN line."""
    with pytest.raises(ValueError, match="fewer than 2 distinct feature values"):
        DropAcceleration(feature=feature).fit(np.ones((1, 1)), np.ones(1))


@pytest.mark.parametrize("feature", ["deflection", "frequency_slope"])
def test_one_sample_acceleration_and_speed_are_warm_up_nan(feature: str) -> None:
    """A fitted estimator fed a single sample answers NaN (warm-up), batch and stream alike."""
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=(3000, 1)), axis=0) * 0.01
    acc = DropAcceleration(feature=feature, speed={"window": 100, "detrend_frames": 50})
    acc.fit(x, np.linspace(0.0, 9.0, 3000))
    one = np.array([[0.5]])
    assert math.isnan(float(acc.predict(one)[0]))
    assert math.isnan(acc.stream().update(one[0]))
    speed = StickSlipSpeed().fit(x, np.full(3000, 10.0))
    with pytest.raises(SlipkitError, match="window 1000 samples"):
        speed.predict(one)  # a recording shorter than the window: an error, not NaN
    assert math.isnan(speed.stream().update(one[0])[1])


# -- DAVIS: empty event frames ---------------------------------------------------------------
def test_empty_event_frames_have_zero_areas_and_no_slip() -> None:
    """A frame without events (zero areas) is a no-incident frame in update_frame, flush and batch."""
    det = DavisPolarity().fit(np.empty((0, 4)))
    state = det.stream()
    results = [state.update_frame(np.empty((0, 4))) for _ in range(3)]
    results.append(state.flush())
    assert [(0, 0, 0)] * 4 == [
        (r.pos_area_px, r.neg_area_px, r.incident) for r in results
    ]
    assert [0, 1, 2, 3] == [r.frame for r in results]
    assert 0 == len(det.frames(np.empty((0, 4))))
