"""BioTac AC-pressure vibration and force-derivative detectors (Su et al. 2015)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import sosfilt

from slipkit import config_dir
from slipkit.data import Dataset
from slipkit.families.biotac.detectors import ForceDerivative, PressureVibration
from slipkit.sim.commands import build_scene

RATE = 2200.0


@lru_cache(maxsize=1)
def simulated() -> Dataset:
    """Three trials of the biotac_lift_slip scene from its real config."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=biotac_lift_slip"])
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    return build_scene(cfg.scene).simulate(3, seed=5)


def stacked(stream: str, channels: list[str]) -> tuple[np.ndarray, ...]:
    """(X, onset labels, segments) of one stream over the simulated trials."""
    xs, ys, segs = [], [], []
    for k, tr in enumerate(simulated()):
        df = tr.streams[stream]
        xs.append(df[channels].to_numpy())
        ys.append((df["t"].to_numpy() >= tr.labels["slip_onset_s"]).astype(int))
        segs.append(np.full(len(df), k))
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(segs)


def burst(n_quiet: int = 660, n_burst: int = 220, seed: int = 0) -> np.ndarray:
    """Quiet 150 Hz hum (2 counts) then a 200 Hz burst of 40 counts, on a 2048 offset."""
    t = np.arange(n_quiet + n_burst) / RATE
    x = 2048.0 + 2.0 * np.sin(2 * np.pi * 150 * t)
    x[n_quiet:] += 40.0 * np.sin(2 * np.pi * 200 * t[n_quiet:])
    x += np.random.default_rng(seed).normal(0, 0.5, len(x))
    return x[:, None]


# -- pressure ---------------------------------------------------------------------------
def steady_gain(det: PressureVibration, f_hz: float) -> float:
    """Amplitude ratio of the detector's band-pass for a sine (after settling)."""
    t = np.arange(int(RATE)) / RATE
    out = sosfilt(det._design(), np.sin(2 * np.pi * f_hz * t))
    return float(np.abs(out[len(out) // 2 :]).max())


def test_band_pass_passes_200_hz_and_rejects_10_hz_and_1_khz() -> None:
    """60-700 Hz band-pass: 200 Hz passes, 10 Hz and 1 kHz are cut below 1 %."""
    det = PressureVibration()
    assert steady_gain(det, 200.0) > 0.95
    assert steady_gain(det, 10.0) < 0.01
    assert steady_gain(det, 1000.0) < 0.01


def test_pressure_fires_on_a_burst_only() -> None:
    """Silent during the baseline and the quiet hum; fires within 22 samples of the burst."""
    X = burst()
    det = PressureVibration().fit(X, np.r_[np.zeros(660), np.ones(220)].astype(int))
    pred = det.predict(X).astype(bool)
    assert not pred[:660].any()
    assert pred[660 : 660 + 22].any()
    assert np.isneginf(det.decision_function(X)[:220]).all()  # baseline warm-up


def test_pressure_score_counts_exceeding_samples() -> None:
    """score >= k exactly when >= 11 of the last 22 rectified samples reach k x baseline."""
    from scipy.signal import sosfilt_zi

    X = burst(seed=1)
    det = PressureVibration(threshold=2.0).fit(X, np.zeros(len(X), int))
    sos = det.sos_
    yf, _ = sosfilt(sos, X[:, 0], zi=sosfilt_zi(sos) * X[0, 0])
    base = max(np.sqrt(np.mean(yf[:220] ** 2)), 1.0)
    s = det.decision_function(X)
    for k in (2.0, 3.0, 5.0):
        for i in range(221, len(X), 7):
            count = int((np.abs(yf[i - 21 : i + 1]) >= k * base).sum())
            assert (count >= 11) == (s[i] >= k)


def test_pressure_batch_equals_streaming_on_simulated_trials() -> None:
    """Concatenated simulated pac recordings: batch with segments == streaming replay."""
    X, y, seg = stacked("pac", ["pac"])
    det = PressureVibration(threshold=None).fit(X, y, segments=seg)
    batch = det.decision_function(X, segments=seg)
    for k in range(3):
        scores, dec = det.replay(X[seg == k])
        np.testing.assert_allclose(batch[seg == k], scores, rtol=1e-12, atol=0)
        assert (batch[seg == k] >= det.threshold_).tolist() == dec.tolist()


def test_fixed_baseline_and_bad_band() -> None:
    """A fixed baseline skips the warm-up; a band beyond Nyquist is a clear error."""
    X = burst()
    det = PressureVibration(baseline=2.0).fit(X, np.zeros(len(X), int))
    assert np.isfinite(det.decision_function(X)[21:]).all()
    with pytest.raises(ValueError, match="band_hz"):
        PressureVibration(band_hz=(60.0, 1200.0)).fit(X, np.zeros(len(X), int))


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 300), level=st.floats(-1e4, 1e4))
def test_pressure_constant_signal_scores_zero(n: int, level: float) -> None:
    """A constant signal never fires: 0 after the warm-up (floor baseline), -inf before."""
    X = np.full((n, 1), level)
    det = PressureVibration(threshold=2.0).fit(X, np.zeros(n, int))
    scores, dec = det.replay(X)
    batch = det.decision_function(X)
    np.testing.assert_array_equal(batch, scores)
    assert not dec.any()
    assert np.isneginf(batch[: min(n, 220)]).all()
    assert (np.abs(batch[220:]) < 1e-6).all()


@settings(max_examples=30, deadline=None)
@given(nan_at=st.lists(st.integers(0, 879), max_size=8))
def test_pressure_nan_policy_agrees_in_batch_and_stream(nan_at: list[int]) -> None:
    """NaN samples score -inf and are held over; batch and streaming agree exactly."""
    X = burst()
    X[nan_at] = np.nan
    det = PressureVibration().fit(burst(), np.zeros(880, int))
    batch = det.decision_function(X)
    scores, dec = det.replay(X)
    np.testing.assert_array_equal(batch, scores)
    assert (batch >= 2.0).tolist() == dec.tolist()
    assert np.isneginf(batch[nan_at]).all()


# -- force derivative ---------------------------------------------------------------------
def ramp(slope: float, n: int = 60) -> np.ndarray:
    """Ft held at 2 N for 30 samples, then changing at ``slope`` N/s (300 Hz)."""
    t = np.arange(n) / 300.0
    return (2.0 + slope * np.clip(t - 0.1, 0, None))[:, None]


@pytest.mark.parametrize(
    ("slope", "fires"), [(-1.0, True), (-0.3, False), (1.0, False), (0.0, False)]
)
def test_force_derivative_fires_on_a_falling_ft_only(slope: float, fires: bool) -> None:
    """dFt/dt < -0.5 N/s is slip; a slow fall, a rise or a hold are not."""
    det = ForceDerivative().fit(ramp(slope), np.zeros(60, int))
    pred = det.predict(ramp(slope)).astype(bool)
    assert fires == bool(pred.any())
    assert not pred[:31].any()


def test_force_derivative_reads_ft_or_fx_fy() -> None:
    """(Fx, Fy) give the same score as Ft = hypot(Fx, Fy); three channels are refused."""
    ft = ramp(-1.0)
    fxy = np.column_stack([0.6 * ft[:, 0], 0.8 * ft[:, 0]])
    a = ForceDerivative().fit(ft, np.zeros(60, int)).decision_function(ft)
    b = ForceDerivative().fit(fxy, np.zeros(60, int)).decision_function(fxy)
    np.testing.assert_allclose(a, b, rtol=1e-12)
    assert 1.0 == pytest.approx(a[40])
    with pytest.raises(ValueError, match="Fx, Fy"):
        ForceDerivative().fit(np.zeros((5, 3)), np.zeros(5))


def test_force_derivative_batch_equals_streaming_on_simulated_trials() -> None:
    """Concatenated simulated (fx, fy) recordings: batch with segments == streaming."""
    X, y, seg = stacked("truth_force", ["fx", "fy"])
    det = ForceDerivative(threshold=None).fit(X, y, segments=seg)
    batch = det.decision_function(X, segments=seg)
    for k in range(3):
        scores, dec = det.replay(X[seg == k])
        np.testing.assert_allclose(batch[seg == k], scores, rtol=1e-12, atol=0)
        assert (batch[seg == k] >= det.threshold_).tolist() == dec.tolist()


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 20),
    level=st.floats(0.0, 50.0),
    nan_at=st.lists(st.integers(0, 19), max_size=4),
)
def test_force_derivative_edge_cases(n: int, level: float, nan_at: list[int]) -> None:
    """Constant, short and NaN-holed signals: no slip, batch == streaming, NaN -> -inf."""
    X = np.full((n, 1), level)
    X[[i for i in nan_at if i < n]] = np.nan
    det = ForceDerivative().fit(np.full((5, 1), level), np.zeros(5, int))
    batch = det.decision_function(X)
    scores, dec = det.replay(X)
    np.testing.assert_array_equal(batch, scores)
    assert not dec.any()
    assert np.isneginf(batch[: min(n, 3)]).all()
