"""SlipTack baselines: eqs. 6-7 frequency, eq. 3 inverted, eqs. 4-5 acceleration, torsional flag."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit import config_dir
from slipkit.data import Dataset
from slipkit.errors import SlipkitError
from slipkit.families.sliptack.accel import DropAcceleration
from slipkit.families.sliptack.physics import (
    ConstantSpeedMotion,
    cycles_constant_speed,
    saturation_frequency,
    stick_slip_frequency,
)
from slipkit.families.sliptack.speed import (
    StickSlipSpeed,
    dominant_frequency,
    f_max_values,
    speed_from_frequency,
)
from slipkit.families.sliptack.torsion import TorsionalSlipDetector
from slipkit.sim.commands import build_scene

RATE = 1000.0
NIB = {"M_kg": 1.4e-5, "k_l_N_m": 9.45}
BASSWOOD = {"normal_force_N": 0.05, "mu_s": 0.55, "mu_k": 0.45, **NIB}


@lru_cache(maxsize=2)
def simulated(scene: str, n: int = 3, seed: int = 1) -> Dataset:
    """A few trials of a SlipTack scene from its real config."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={scene}"])
    GlobalHydra.instance().clear()
    return build_scene(cfg.scene).simulate(n, seed=seed)


def stick_slip_signal(v_mm_s: float, duration_s: float = 1.5) -> np.ndarray:
    """Nib deflection (mm) of the exact oscillator pulled at ``v_mm_s`` (basswood)."""
    motion = ConstantSpeedMotion(v_mm_s * 1e-3, 0.0, BASSWOOD["normal_force_N"])
    cycles = cycles_constant_speed(
        motion, duration_s, BASSWOOD["mu_s"], BASSWOOD["mu_k"], **NIB
    )
    t = np.arange(int(duration_s * RATE)) / RATE
    return 1e3 * cycles.evaluate(t)


# -- eqs. 6-7 ----------------------------------------------------------------------------------
def test_f_max_values_are_the_papers_26() -> None:
    """Eq. 7 averages over f_max = 15, 16, ..., 40 Hz: 26 values."""
    values = f_max_values((15.0, 40.0))
    assert 26 == len(values)
    assert (15.0, 40.0) == (values[0], values[-1])


@pytest.mark.parametrize("f0", [18.0, 25.0, 33.0])
def test_single_sinusoid_frequency_is_recovered(f0: float) -> None:
    """A pure sinusoid's f_d is its frequency once sidelobe maxima are left out."""
    t = np.arange(2000) / RATE
    f = dominant_frequency(np.sin(2 * np.pi * f0 * t), RATE, min_peak_ratio=0.5)
    assert f0 == pytest.approx(f, abs=0.5)


def test_top_peak_average_follows_eq_6() -> None:
    """Two tones below every f_max: f_i is the mean over j of the top-j means (eq. 6)."""
    t = np.arange(4000) / RATE
    x = 2.0 * np.sin(2 * np.pi * 10.0 * t) + np.sin(2 * np.pi * 12.0 * t)
    f = dominant_frequency(x, RATE, min_peak_ratio=0.3)
    # peaks: 10 Hz (k=1), 12 Hz (k=2); j=1 -> 10, j>=2 -> 11; f_i = (10 + 9 * 11) / 10
    assert (10.0 + 9 * 11.0) / 10 == pytest.approx(f, abs=0.05)


def test_stick_slip_signal_frequency_matches_the_exact_model() -> None:
    """f_d of the integrated oscillator at 40 mm/s is the exact eq.-3 frequency (1 Hz bins)."""
    x = stick_slip_signal(40.0)[500:]
    expected = float(stick_slip_frequency(0.04, form="exact", **BASSWOOD))
    f = dominant_frequency(x, RATE, min_peak_ratio=0.6, f_max_range=(15.0, 100.0))
    assert expected == pytest.approx(f, abs=1.0)


def test_literal_paper_averaging_is_biased_on_a_clean_signal() -> None:
    """With every local maximum counted (the paper's text), noise peaks pull f_d far off."""
    rng = np.random.default_rng(0)
    x = stick_slip_signal(40.0)[500:] + rng.normal(0, 0.01, 1000)
    expected = float(stick_slip_frequency(0.04, form="exact", **BASSWOOD))
    literal = dominant_frequency(x, RATE)
    assert abs(literal - expected) > 5.0


@settings(max_examples=25, deadline=None)
@given(
    value=st.floats(-1e3, 1e3, allow_nan=False),
    n=st.integers(0, 600),
)
def test_constant_signal_has_no_frequency(value: float, n: int) -> None:
    """A flat window (any level, any length) has no stick-slip: f_d is NaN, no warning."""
    assert np.isnan(dominant_frequency(np.full(n, value), RATE))


def test_nan_sample_makes_the_window_undefined() -> None:
    """A dropped (NaN) sample in the window gives NaN rather than a wrong frequency."""
    x = np.sin(np.arange(500) / 10.0)
    x[100] = np.nan
    assert np.isnan(dominant_frequency(x, RATE))


# -- eq. 3 inverted ----------------------------------------------------------------------------
@pytest.mark.parametrize("form", ["exact", "paper"])
def test_speed_inversion_round_trips_the_law(form: str) -> None:
    """speed_from_frequency(f(v)) == v over 1-500 mm/s, both forms, to 1e-9 relative."""
    v = np.geomspace(1e-3, 0.5, 40)
    f = stick_slip_frequency(v, form=form, **BASSWOOD)  # type: ignore[arg-type]
    back = speed_from_frequency(f, form=form, **BASSWOOD)  # type: ignore[arg-type]
    np.testing.assert_allclose(back, v, rtol=1e-9)


@settings(max_examples=40, deadline=None)
@given(
    v=st.floats(1e-4, 10.0),
    fn=st.floats(1e-3, 1.0),
    mu_k=st.floats(0.05, 1.0),
    gap=st.floats(0.01, 0.5),
    form=st.sampled_from(["exact", "paper"]),
)
def test_inversion_round_trips_random_parameters(
    v: float, fn: float, mu_k: float, gap: float, form: str
) -> None:
    """For any load, friction pair and speed (0.1 mm/s to 10 m/s) the inverse reproduces
    the frequency; speeds close to saturation are ill-conditioned, so f is compared."""
    p = {"normal_force_N": fn, "mu_s": mu_k + gap, "mu_k": mu_k, **NIB}
    f = stick_slip_frequency(v, form=form, **p)  # type: ignore[arg-type]
    back = speed_from_frequency(f, form=form, **p)  # type: ignore[arg-type]
    again = stick_slip_frequency(back, form=form, **p)  # type: ignore[arg-type]
    assert float(f) == pytest.approx(float(again), rel=1e-12)


@pytest.mark.parametrize("form", ["exact", "paper"])
def test_saturation_and_beyond_is_refused_as_nan(form: str) -> None:
    """At and above saturation, at 0, negative, NaN or inf frequency: NaN, no warnings."""
    fs = float(saturation_frequency(NIB["M_kg"], NIB["k_l_N_m"], form=form))  # type: ignore[arg-type]
    f = np.array([fs, fs * 1.5, 0.0, -3.0, np.nan, np.inf])
    with np.errstate(all="raise"):
        out = speed_from_frequency(f, form=form, **BASSWOOD)  # type: ignore[arg-type]
    assert np.isnan(out).all()


@pytest.mark.parametrize("rel", [1e-3, 1e-6, 1e-9])
def test_just_below_saturation_is_finite_and_consistent(rel: float) -> None:
    """Close below 1/tau_slip the speed is huge but finite, rises as f nears saturation,
    and the law maps it back to f (the ill-conditioned hard case)."""
    fs = float(saturation_frequency(NIB["M_kg"], NIB["k_l_N_m"], form="exact"))
    f = fs * (1 - np.array([10 * rel, rel]))
    v = speed_from_frequency(f, form="exact", **BASSWOOD)
    assert np.isfinite(v).all()
    assert v[1] > v[0] > 0.5  # m/s: far beyond the 10-100 mm/s pull speeds
    back = stick_slip_frequency(v, form="exact", **BASSWOOD)
    np.testing.assert_allclose(back, f, rtol=1e-12)


def test_unknown_form_is_refused() -> None:
    """form must be exact or paper."""
    with pytest.raises(ValueError, match="form"):
        speed_from_frequency(10.0, form="other", **BASSWOOD)  # type: ignore[arg-type]


# -- StickSlipSpeed ----------------------------------------------------------------------------
def pull_xy(ds: Dataset) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xs, ys, segs = [], [], []
    for k, tr in enumerate(ds):
        xs.append(tr.streams["nib"]["deflection"].to_numpy())
        ys.append(tr.streams["truth_motion"]["speed"].to_numpy())
        segs.append(np.full(len(xs[-1]), k))
    return np.concatenate(xs)[:, None], np.concatenate(ys), np.concatenate(segs)


def speed_estimator(**kw: object) -> StickSlipSpeed:
    params: dict[str, object] = {
        "window": 500,
        "hop": 25,
        "min_peak_ratio": 0.6,
        "f_max_range": (15.0, 100.0),
        **kw,
    }
    return StickSlipSpeed(**params)  # type: ignore[arg-type]


def test_speed_batch_equals_streaming() -> None:
    """Replaying a simulated pull sample by sample gives the batch frequencies and speeds."""
    X, y, seg = pull_xy(simulated("sliptack_pull"))
    est = speed_estimator().fit(X, y, segments=seg)
    one = X[seg == 0]
    f_batch, v_batch = est.frequency(one), est.predict(one)
    state = est.stream()
    rows = np.array([state.update(s) for s in one])
    np.testing.assert_array_equal(f_batch, rows[:, 0])
    np.testing.assert_array_equal(v_batch, rows[:, 1])


def test_speed_of_a_known_pull() -> None:
    """On the exact oscillator at 40 mm/s the estimator reads 40 mm/s within 5%."""
    x = stick_slip_signal(40.0, 2.0)
    est = speed_estimator(window=1000, **{k: BASSWOOD[k] for k in ("mu_s", "mu_k")})
    est.fit(x[:, None], np.full(len(x), 40.0))
    v = est.predict(x[:, None])
    assert 40.0 == pytest.approx(np.nanmedian(v[1500:]), rel=0.05)


def test_calibration_recovers_the_stick_length() -> None:
    """calibrate=True with a wrong normal force finds the physical stick length again."""
    x = np.concatenate([stick_slip_signal(v, 2.0) for v in (30.0, 60.0)])
    y = np.repeat([30.0, 60.0], 2000)
    seg = np.repeat([0, 1], 2000)
    good = speed_estimator(window=1000).fit(x[:, None], y, segments=seg)
    cal = speed_estimator(window=1000, normal_force_N=0.1, calibrate=True)
    cal.fit(x[:, None], y, segments=seg)
    assert good.stick_length_m_ == pytest.approx(cal.stick_length_m_, rel=0.05)


def test_window_longer_than_the_recording_is_an_error_naming_both() -> None:
    """A recording shorter than the window is a SlipkitError naming both lengths (the stream warms up: NaN)."""
    x = np.sin(np.arange(100) / 5.0)[:, None]
    est = speed_estimator().fit(x, np.full(100, 10.0))
    with pytest.raises(
        SlipkitError,
        match=r"window 500 samples \(0.5 s at 1000 Hz\) is longer than "
        r"the recording \(100 samples, 0.1 s\)",
    ):
        est.predict(x)
    assert all(np.isnan(est.stream().update(s)[1]) for s in x)


def test_short_segment_is_named() -> None:
    """With segments, the short recording is named by its index."""
    x = np.sin(np.arange(700) / 5.0)[:, None]
    seg = np.r_[np.zeros(600, int), np.ones(100, int)]
    est = speed_estimator().fit(x[:600], np.full(600, 10.0))
    with pytest.raises(SlipkitError, match=r"recording 1 \(0-based\) \(100 samples"):
        est.frequency(x, segments=seg)


def test_speed_segments_restart_the_window() -> None:
    """Each recording warms up on its own: a new segment is NaN for window-1 samples."""
    X, y, seg = pull_xy(simulated("sliptack_pull"))
    est = speed_estimator().fit(X, y, segments=seg)
    f = est.frequency(X, segments=seg)
    start = int(np.flatnonzero(seg == 1)[0])
    assert np.isnan(f[start : start + 499]).all()
    np.testing.assert_array_equal(est.frequency(X[seg == 1]), f[seg == 1])


def test_speed_needs_one_channel() -> None:
    """Two channels are refused with a message naming the nib signal."""
    with pytest.raises(ValueError, match=r"1 channel\(s\) \(the nib signal"):
        speed_estimator().fit(np.zeros((10, 2)), np.zeros(10))


# -- acceleration -------------------------------------------------------------------------------
def drop_xy(ds: Dataset) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xs, ys, segs = [], [], []
    for k, tr in enumerate(ds):
        xs.append(tr.streams["nib"]["deflection"].to_numpy())
        t = tr.streams["truth_motion"]["t"].to_numpy()
        a = tr.streams["truth_motion"]["acceleration"].to_numpy()
        ys.append(np.where(t >= tr.labels["release_s"] + 0.06, a, np.nan))
        segs.append(np.full(len(xs[-1]), k))
    return np.concatenate(xs)[:, None], np.concatenate(ys), np.concatenate(segs)


def test_deflection_calibration_follows_eq_4() -> None:
    """On the drop, acceleration regressed on gross deflection is a falling line, |r| ~ 1."""
    X, y, seg = drop_xy(simulated("sliptack_drop", 4))
    est = DropAcceleration(feature="deflection").fit(X, y, segments=seg)
    assert est.coef_ < 0
    assert est.r_ < -0.7


@pytest.mark.parametrize("feature", ["deflection", "frequency_slope"])
def test_acceleration_batch_equals_streaming(feature: str) -> None:
    """Both acceleration features give the same values sample by sample as in batch."""
    X, y, seg = drop_xy(simulated("sliptack_drop", 4))
    est = DropAcceleration(feature=feature).fit(X, y, segments=seg)
    one = X[seg == 1]
    state = est.stream()
    streamed = np.array([state.update(s) for s in one])
    np.testing.assert_allclose(streamed, est.predict(one), rtol=1e-10, atol=1e-12)


def test_acceleration_without_distinct_features_is_refused() -> None:
    """A flat signal cannot calibrate eq. 4's line: a clear error, not a NaN fit."""
    with pytest.raises(ValueError, match="distinct feature"):
        DropAcceleration().fit(np.ones((100, 1)), np.ones(100))


# -- torsional flag ----------------------------------------------------------------------------
def burst(n: int = 3000, start: int = 1500) -> tuple[np.ndarray, np.ndarray]:
    """Noise, then a 10 Hz oscillation from ``start`` (torsional slip), and its labels."""
    rng = np.random.default_rng(4)
    t = np.arange(n) / RATE
    x = rng.normal(0, 0.01, n) + np.where(
        np.arange(n) >= start, np.sin(2 * np.pi * 10 * t), 0
    )
    return x[:, None], (np.arange(n) >= start).astype(int)


def test_torsional_flag_fires_on_a_10hz_burst() -> None:
    """The ROC-chosen threshold separates the 10 Hz burst from the noise before it."""
    X, y = burst()
    det = TorsionalSlipDetector().fit(X, y)
    pred = det.predict(X)
    assert 0 == pred[:1400].sum()
    assert 1 == pred[-500:].min()
    assert det.auc_ > 0.95


def test_torsional_batch_equals_streaming() -> None:
    """The band-power flag decides the same sample by sample as in batch."""
    X, y = burst()
    det = TorsionalSlipDetector().fit(X, y)
    scores, dec = det.replay(X)
    np.testing.assert_allclose(scores, det.decision_function(X), rtol=1e-9)
    np.testing.assert_array_equal(dec.astype(int), det.predict(X))
