"""Detectors whose conventions are explicit and checked (issue 14): FSR polarity and sharp
bumps, SlipTack rates, harmonics and normal force.

The FSR signals here come from a small generator written for these tests, independent of
``slipkit.sim`` (its own force shapes, its own force-to-voltage law, either wiring):
a press, a hold, then either a slide made of stick-slip events (a sudden force drop of
5-15 % with a short ring, then a linear stick ramp back) or sharp impulsive bumps (+-15-50 %
of the holding force, 1-5 ms edges, 5-50 ms long, at least 0.4 s apart). Run this file
as a script to print the detection table quoted in ``docs/families/fsr.md``::

    .venv/bin/python tests/baselines/test_conventions.py
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from slipkit.errors import SlipkitError
from slipkit.families.fsr.touch_slip import FSRTouchSlip, PolarityWarning
from slipkit.families.sliptack.speed import (
    FixedNormalForceWarning,
    StickSlipSpeed,
    parabolic_offset,
)

RATE = 2000.0  # Hz


# -- an independent FSR signal generator ------------------------------------------------
@dataclass
class FSRTrial:
    """One generated recording: voltage (V) and what happened when (s)."""

    v: np.ndarray
    slide: tuple[float, float] | None  # (start, end) of the slide
    events: list[float] = field(default_factory=list)  # stick-slip onsets
    bumps: list[tuple[float, float]] = field(default_factory=list)  # (start, end)

    @property
    def t(self) -> np.ndarray:
        return np.arange(len(self.v)) / RATE


def _volts(force: np.ndarray, polarity: str) -> np.ndarray:
    """A saturating divider law (not the simulator's eq. 6): 0 N at rest, 3 V span."""
    u = 3.0 * force / (force + 2.0)
    return 4.2 - u if polarity == "falling" else 0.4 + u


def fsr_trial(
    rng: np.random.Generator, *, polarity: str, slide: bool, noise_V: float = 2e-3
) -> FSRTrial:
    """A press to 1-5 N, then a 1-3 s slide (``slide``) or a 2 s hold with sharp bumps."""
    f0 = rng.uniform(1.0, 5.0)
    rest_s, rise_s = 0.1, 0.01
    hold_s = 0.5 if slide else 2.0
    slide_s = rng.uniform(1.0, 3.0) if slide else 0.0
    t0 = rest_s + rise_s + hold_s  # slide start
    n = int((t0 + slide_s + 0.05) * RATE)
    t = np.arange(n) / RATE
    force = np.clip((t - rest_s) / rise_s, 0.0, 1.0) * f0
    trial = FSRTrial(v=np.empty(0), slide=(t0, t0 + slide_s) if slide else None)
    if slide:
        onsets = []
        e = t0 + rng.uniform(0.02, 0.1)
        while e < t0 + slide_s - 0.02:
            onsets.append(e)
            e += rng.uniform(0.04, 0.2)  # 5-25 events per second
        for e, nxt in itertools.pairwise([*onsets, t0 + slide_s]):
            drop = rng.uniform(0.05, 0.15) * f0
            fall = rng.uniform(5e-4, 2e-3)
            dt = t - e
            on = (dt >= 0) & (t < nxt)
            shape = np.where(
                dt < fall, dt / fall, 1.0 - (dt - fall) / max(nxt - e - fall, 1e-3)
            )
            ring_hz = rng.uniform(80.0, 180.0)
            tau = np.maximum(dt, 0.0)
            ring = 0.3 * np.exp(-tau / 4e-3) * np.sin(2 * np.pi * ring_hz * tau)
            force[on] -= drop * (shape[on] + ring[on] * (dt[on] >= fall))
        trial.events = onsets
    else:
        b = rest_s + rise_s + 0.1 + rng.uniform(0.0, 0.3)
        while b < t0 - 0.1:
            amp = rng.choice([-1.0, 1.0]) * rng.uniform(0.15, 0.5) * f0
            edge = rng.uniform(1e-3, 5e-3)
            length = rng.uniform(max(5e-3, 2 * edge), 50e-3)
            dt = t - b
            up = np.clip(dt / edge, 0.0, 1.0)
            down = np.clip((length - dt) / edge, 0.0, 1.0)
            force += amp * np.minimum(up, down) * (dt >= 0)
            trial.bumps.append((b, b + length))
            b += length + rng.uniform(0.4, 0.8)
    trial.v = _volts(np.maximum(force, 0.0), polarity) + rng.normal(0.0, noise_V, n)
    return trial


def fsr_trials(seed: int, n: int, *, polarity: str, slide: bool) -> list[FSRTrial]:
    """``n`` trials; trial ``i`` draws from ``default_rng([seed, i])``."""
    return [
        fsr_trial(np.random.default_rng([seed, i]), polarity=polarity, slide=slide)
        for i in range(n)
    ]


def event_labels(trial: FSRTrial, width_s: float = 0.01) -> np.ndarray:
    """1 for ``width_s`` after each stick-slip onset (the paper's induced-slip unit)."""
    t = trial.t
    y = np.zeros(len(t), int)
    for e in trial.events:
        y[(t >= e) & (t < e + width_s)] = 1
    return y


def stack(trials: list[FSRTrial]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X, event labels, segments) of the trials."""
    X = np.concatenate([tr.v for tr in trials])[:, None]
    y = np.concatenate([event_labels(tr) for tr in trials])
    seg = np.concatenate([np.full(len(tr.v), k) for k, tr in enumerate(trials)])
    return X, y, seg


def event_alpha(polarity: str) -> float:
    """Alpha (V/s) on the event ROC of 12 training slides (seed 100), as the paper and
    the detection task do: each stick-slip onset is a positive unit (its largest score
    within 10 ms), each 10 ms window before the slide a negative one; Youden's J."""
    from sklearn.metrics import roc_curve

    trials = fsr_trials(100, 12, polarity=polarity, slide=True)
    X, y, seg = stack(trials)
    det = FSRTouchSlip(threshold=0.0).fit(X, y, segments=seg)
    pos, neg = [], []
    for tr in trials:
        assert tr.slide is not None
        s, t = det.decision_function(tr.v[:, None]), tr.t
        pos += [s[(t >= e) & (t < e + 0.01)].max() for e in tr.events]
        held = s[(t >= 0.12) & (t < tr.slide[0])]
        neg += [w.max() for w in np.array_split(held, max(1, len(held) // 20))]
    units = np.maximum(np.r_[pos, neg], -1e300)
    fpr, tpr, thr = roc_curve(np.r_[np.ones(len(pos)), np.zeros(len(neg))], units)
    return float(thr[1:][np.argmax((tpr - fpr)[1:])])


def fit_on_slides(polarity: str, **params: object) -> FSRTouchSlip:
    """A detector with the event-ROC alpha of :func:`event_alpha` (same for both forms)."""
    X, y, seg = stack(fsr_trials(100, 12, polarity=polarity, slide=True))
    det = FSRTouchSlip(threshold=event_alpha(polarity), **params)  # type: ignore[arg-type]
    return det.fit(X, y, segments=seg)


def detection_rates(
    det: FSRTouchSlip, slides: list[FSRTrial], bumped: list[FSRTrial]
) -> dict[str, float]:
    """Slides detected during the slide; bumps that fired within their span + 50 ms."""
    hit = 0
    for tr in slides:
        assert tr.slide is not None
        fired = det.predict(tr.v[:, None]).astype(bool)
        hit += bool(fired[(tr.t >= tr.slide[0]) & (tr.t <= tr.slide[1])].any())
    n_bumps = fired_bumps = 0
    for tr in bumped:
        fired = det.predict(tr.v[:, None]).astype(bool)
        for a, z in tr.bumps:
            n_bumps += 1
            fired_bumps += bool(fired[(tr.t >= a) & (tr.t <= z + 0.05)].any())
    return {
        "slides": hit / len(slides),
        "n_slides": len(slides),
        "bumps_fired": fired_bumps / n_bumps if n_bumps else float("nan"),
        "n_bumps": n_bumps,
    }


#: configs/detector/fsr_robust.yaml
ROBUST = {"confirm_events": 3, "confirm_window_s": 0.4, "peak_gap_s": 0.01}


# -- polarity -------------------------------------------------------------------------------
@pytest.mark.parametrize("polarity", ["falling", "rising"])
def test_fit_learns_the_wiring_polarity(polarity: str) -> None:
    """polarity=auto learns falling / rising from the training presses."""
    X, y, seg = stack(fsr_trials(1, 3, polarity=polarity, slide=True))
    det = FSRTouchSlip().fit(X, y, segments=seg)
    assert polarity == det.polarity_
    assert {polarity: 3, "untouched": 0} == {
        k: det.polarity_votes_[k] for k in (polarity, "untouched")
    }


@pytest.mark.parametrize("polarity", ["falling", "rising"])
def test_either_polarity_detects_the_slides(polarity: str) -> None:
    """The paper detector with a learned polarity finds >= 95 % of generated slides."""
    det = fit_on_slides(polarity)
    slides = fsr_trials(200, 20, polarity=polarity, slide=True)
    rates = detection_rates(det, slides, [])  # type: ignore[arg-type]
    assert rates["slides"] >= 0.95


def test_training_data_without_a_touch_is_refused_with_a_fixed_threshold() -> None:
    """A fixed threshold with polarity=auto and never-pressed data is an error naming the data."""
    X = np.full((400, 1), 4.5) + np.random.default_rng(0).normal(0, 1e-3, (400, 1))
    with pytest.raises(
        SlipkitError, match=r"1 recording\(s\), 400 samples\) never shows"
    ):
        FSRTouchSlip(threshold=8.0).fit(X, np.zeros(400, int))


def test_roc_fit_without_a_touch_is_refused_not_a_traceback() -> None:
    """ROC calibration on never-pressed recordings is a SlipkitError, not an argmax crash."""
    X = np.full((400, 1), 0.4)
    y = np.r_[np.zeros(200, int), np.ones(200, int)]
    with pytest.raises(SlipkitError, match="set polarity"):
        FSRTouchSlip().fit(X, y, segments=np.repeat([0, 1], 200))


def test_recordings_of_both_wirings_fall_back_to_per_recording_with_a_warning() -> None:
    """One falling and one rising training recording: a warning naming both, sign per recording."""
    a = fsr_trials(3, 1, polarity="falling", slide=True)
    b = fsr_trials(4, 1, polarity="rising", slide=True)
    X, y, seg = stack(a + b)
    with pytest.warns(PolarityWarning, match=r"recordings \[0\] fall, \[1\] rise"):
        det = FSRTouchSlip(threshold=event_alpha("falling")).fit(X, y, segments=seg)
    assert "per_recording" == det.polarity_


@pytest.mark.parametrize("params", [{}, ROBUST], ids=["paper", "confirmed"])
def test_per_recording_polarity_detects_either_wiring_and_streams_alike(
    params: dict[str, object],
) -> None:
    """polarity=per_recording: slides of both wirings detected, bumps ignored (confirmed), batch == stream."""
    alpha = event_alpha("falling")
    det = FSRTouchSlip(threshold=alpha, polarity="per_recording", **params)
    X, y, seg = stack(fsr_trials(100, 2, polarity="rising", slide=True))
    det.fit(X, y, segments=seg)
    for polarity in ("falling", "rising"):
        slides = fsr_trials(200, 10, polarity=polarity, slide=True)
        bumped = fsr_trials(500, 10, polarity=polarity, slide=False)
        rates = detection_rates(det, slides, bumped)
        assert rates["slides"] >= 0.95
        if params:
            assert rates["bumps_fired"] <= 0.10
        for tr in slides[:1] + bumped[:1]:
            scores, dec = det.replay(tr.v[:, None])
            batch = det.decision_function(tr.v[:, None])
            np.testing.assert_array_equal(batch, scores)
            assert (batch >= alpha).tolist() == dec.tolist()


def test_per_recording_polarity_exports_with_the_press_sign_op() -> None:
    """A per-recording sign exports: the graph asks the runtime for press_sign first
    (parity: tests/families/fsr/test_press_sign.py)."""
    from slipkit.families.fsr.export.touch_slip import export_fsr_touch_slip

    X, y, seg = stack(fsr_trials(100, 2, polarity="rising", slide=True))
    det = FSRTouchSlip(threshold=8.0, polarity="per_recording").fit(X, y, segments=seg)
    graph = export_fsr_touch_slip(det)
    assert ["press_sign"] == [s["op"] for s in graph.preprocessing]


def test_force_input_refuses_a_calibration_of_the_other_wiring() -> None:
    """input=force with the falling-wiring calibration on a rising recording is refused."""
    X, y, seg = stack(fsr_trials(5, 2, polarity="rising", slide=True))
    with pytest.raises(SlipkitError, match="falling force"):
        FSRTouchSlip(input="force").fit(X, y, segments=seg)


def test_unfitted_auto_polarity_names_what_is_needed() -> None:
    """Asking an unfitted auto detector for its slip sign says fit or set polarity."""
    with pytest.raises(SlipkitError, match="call fit, or set polarity"):
        _ = FSRTouchSlip()._sign


@pytest.mark.parametrize("polarity", ["falling", "rising"])
@pytest.mark.parametrize("params", [{}, ROBUST], ids=["paper", "confirmed"])
def test_batch_equals_streaming_for_either_polarity(
    polarity: str, params: dict[str, object]
) -> None:
    """Batch scores equal the streaming replay for either wiring, paper and confirmed forms."""
    det = fit_on_slides(polarity, **params)
    for tr in fsr_trials(300, 2, polarity=polarity, slide=True) + fsr_trials(
        301, 1, polarity=polarity, slide=False
    ):
        batch = det.decision_function(tr.v[:, None])
        scores, dec = det.replay(tr.v[:, None])
        np.testing.assert_array_equal(batch, scores)
        assert (batch >= det.threshold_).tolist() == dec.tolist()


@pytest.mark.parametrize("polarity", ["falling", "rising"])
def test_onnx_graph_agrees_for_either_polarity(polarity: str) -> None:
    """The exported FSR graph (rest from fit) passes parity on generated recordings."""
    from slipkit.export.detectors import check_detector_parity
    from slipkit.families.fsr.export.touch_slip import export_fsr_touch_slip

    det = fit_on_slides(polarity)
    X, _, seg = stack(fsr_trials(400, 3, polarity=polarity, slide=True))
    graph = export_fsr_touch_slip(det)
    report = check_detector_parity(det, graph, X, segments=seg)
    assert polarity == graph.features["polarity"]
    assert (True, 0) == (report["passed"], report["n_finite_mismatch"])


@pytest.mark.parametrize("polarity", ["falling", "rising"])
def test_confirmed_graph_agrees_on_slides_and_bumps(polarity: str) -> None:
    """The confirmed variant's graph (k-th largest peak over the window) passes parity, slides and bumps."""
    from slipkit.export.detectors import check_detector_parity
    from slipkit.families.fsr.export.touch_slip import export_fsr_touch_slip

    det = fit_on_slides(polarity, **ROBUST)
    trials = fsr_trials(400, 2, polarity=polarity, slide=True) + fsr_trials(
        401, 2, polarity=polarity, slide=False
    )
    X, _, seg = stack(trials)
    graph = export_fsr_touch_slip(det)
    report = check_detector_parity(det, graph, X, segments=seg)
    assert (845, 3) == (graph.window, graph.features["confirm_events"])
    assert (True, 0) == (report["passed"], report["n_finite_mismatch"])
    assert report["max_abs_diff"] <= 1e-3 * det.threshold_
    assert det.predict(X, segments=seg).any()  # the comparison includes slip decisions


# -- sharp bumps ------------------------------------------------------------------------------
@pytest.mark.parametrize("polarity", ["falling", "rising"])
def test_confirmed_detector_holds_against_sharp_bumps(polarity: str) -> None:
    """Confirmed variant: >= 95 % of slides, <= 10 % of sharp bumps fire; the paper's fires more."""
    slides = fsr_trials(200, 20, polarity=polarity, slide=True)
    bumped = fsr_trials(500, 20, polarity=polarity, slide=False)
    robust = detection_rates(fit_on_slides(polarity, **ROBUST), slides, bumped)
    paper = detection_rates(fit_on_slides(polarity), slides, bumped)
    assert robust["slides"] >= 0.95
    assert robust["bumps_fired"] <= 0.10
    assert paper["bumps_fired"] > robust["bumps_fired"]


def test_one_bump_is_one_event_two_events_confirm() -> None:
    """One sharp release is one peak (no score); a second within the window confirms it."""
    v = np.full(800, 4.5)
    v[40:] = 2.5
    v[300:305] += 0.3  # a one-block release: a bump's edge
    det = FSRTouchSlip(threshold=10.0, confirm_events=2, confirm_window_s=0.3)
    det.fit(v[:, None], np.zeros(800, int))
    assert 0 == int(det.predict(v[:, None]).sum())
    v2 = v.copy()
    v2[500:505] += 0.3  # a second release 0.1 s later
    fired = det.predict(v2[:, None])
    assert (0, 1) == (int(fired[:500].max()), int(fired[510:].max()))


def main() -> None:
    """Print the slide / bump table quoted in docs/families/fsr.md."""
    print(
        "FSR on generated signals (tests/baselines/test_conventions.py): 20 slides "
        "(seed 200), 20 bump trials (seed 500), alpha from the event ROC of 12 "
        "training slides (seed 100)"
    )
    print(
        f"{'polarity':9s} {'detector':24s} {'alpha':>8s} {'slides':>14s} {'bumps fired':>16s}"
    )
    for polarity in ("falling", "rising"):
        slides = fsr_trials(200, 20, polarity=polarity, slide=True)
        bumped = fsr_trials(500, 20, polarity=polarity, slide=False)
        for name, params in (("paper (fsr)", {}), ("confirmed (fsr_robust)", ROBUST)):
            det = fit_on_slides(polarity, **params)
            r = detection_rates(det, slides, bumped)
            print(
                f"{polarity:9s} {name:24s} {det.threshold_:8.2f} "
                f"{r['slides']:7.0%} of {r['n_slides']:3d} "
                f"{r['bumps_fired']:7.0%} of {r['n_bumps']:3d}"
            )


if __name__ == "__main__":
    main()


# -- SlipTack: rates, harmonics, normal force -------------------------------------------------
def sliptack_config(**over: object) -> StickSlipSpeed:
    """configs/detector/sliptack_frequency.yaml (basswood friction), unfitted."""
    from omegaconf import OmegaConf

    from slipkit import config_dir

    cfg = OmegaConf.to_container(
        OmegaConf.load(config_dir() / "detector" / "sliptack_frequency.yaml")
    )
    assert isinstance(cfg, dict)
    params = {k: v for k, v in cfg.items() if not str(k).startswith("_")}
    return StickSlipSpeed(**{**params, **over})  # type: ignore[arg-type]


def _fit(est: StickSlipSpeed, channels: int = 1) -> StickSlipSpeed:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FixedNormalForceWarning)
        return est.fit(np.zeros((1, channels)), np.full(1, np.nan))


def test_band_above_nyquist_is_refused_naming_rate_and_band() -> None:
    """At 30 Hz the shipped f_max band (up to 100 Hz) is refused, naming the rate and the band."""
    with pytest.raises(
        SlipkitError,
        match=r"f_max_range \[15.0, 100.0\] Hz reaches the Nyquist limit 15 Hz of "
        r"rate_hz 30 Hz",
    ):
        _fit(sliptack_config(rate_hz=30.0, window=60))


def test_band_below_nyquist_still_refused_when_stick_slip_can_alias() -> None:
    """A band below 15 Hz at 30 Hz is refused too (saturation 130.8 Hz aliases) unless allowed, then flagged."""
    est = sliptack_config(rate_hz=30.0, window=60, f_max_range=[5.0, 14.0])
    with pytest.raises(SlipkitError, match=r"saturation \(130.8 Hz\) aliases"):
        _fit(est)
    flagged = _fit(est.set_params(allow_aliasing=True))
    assert 15.0 == flagged.nyquist_hz_
    assert np.isfinite(flagged.alias_speed_mm_s_)
    assert np.isnan(_fit(sliptack_config()).alias_speed_mm_s_)  # 1 kHz: none


def _two_tone(f0: float, n: int = 3000, seed: int = 0) -> np.ndarray:
    t = np.arange(n) / 1000.0
    rng = np.random.default_rng(seed)
    return (
        0.1 * np.sin(2 * np.pi * f0 * t + rng.uniform(0, 6))
        + 0.063 * np.sin(4 * np.pi * f0 * t + rng.uniform(0, 6))
        + rng.normal(0.0, 0.01, n)
    )


@pytest.mark.parametrize("f0", [25.0, 30.0, 44.0])
def test_strong_second_harmonic_reads_as_the_fundamental(f0: float) -> None:
    """A 0.63 second harmonic passing the 0.6 peak cut-off: shipped config within 1 %, harmonics kept > 10 % off."""
    x = _two_tone(f0)[:, None]
    shipped = _fit(sliptack_config())
    paper_peaks = _fit(sliptack_config(harmonics="keep", interpolate=False))
    assert abs(np.nanmedian(shipped.frequency(x)) - f0) / f0 <= 0.01
    assert abs(np.nanmedian(paper_peaks.frequency(x)) - f0) / f0 > 0.1


@pytest.mark.parametrize("f0", [20.5, 33.33, 57.8])
def test_interpolation_resolves_below_the_dft_bin(f0: float) -> None:
    """Between bins (1 Hz at 1000 samples) the interpolated frequency is within 0.2 % of the tone."""
    t = np.arange(2000) / 1000.0
    x = (0.3 + 0.05 * np.sin(2 * np.pi * f0 * t))[:, None]
    f = np.nanmedian(_fit(sliptack_config()).frequency(x))
    assert abs(f - f0) / f0 <= 0.002


def test_shipped_config_meets_the_frequency_targets_on_the_pull_scene() -> None:
    """sliptack_pull, 6 wood trials (seed 5): |f_d - f_model| <= 1 % mean and <= 3 % worst."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from slipkit import config_dir
    from slipkit.sim.commands import build_scene

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="simulate",
            overrides=["scene=sliptack_pull", "scene.model.materials=[basswood]"],
        )
    GlobalHydra.instance().clear()
    est = _fit(sliptack_config())
    err = []
    for tr in build_scene(cfg.scene).simulate(6, seed=5):
        x = tr.streams["nib"]["deflection"].to_numpy()
        t = tr.streams["nib"]["t"].to_numpy()
        f = est.frequency(x[t >= tr.labels["slip_onset_s"]][:, None])
        f_model = float(est.frequency_from_speed(tr.labels["speed_mm_s"]))
        err.append(abs(float(np.nanmedian(f)) - f_model) / f_model)
    assert np.mean(err) <= 0.01
    assert np.max(err) <= 0.03


def test_fixed_normal_force_warns_and_states_the_sensitivity() -> None:
    """A fixed normal force warns (speed error = force error, 1:1) and records where the force comes from."""
    with pytest.warns(
        FixedNormalForceWarning, match="a force 30 % off gives a speed 30 % off"
    ):
        est = sliptack_config().fit(np.zeros((1, 1)), np.full(1, np.nan))
    assert ("value 0.05 N", 1.0) == (est.normal_force_source_, est.speed_per_force_)


def test_speed_scales_with_the_input_normal_force_batch_and_stream() -> None:
    """normal_force=input: speed at 2 Fn is twice the speed at Fn; batch equals streaming."""
    x = _two_tone(31.3, n=1500)
    est = _fit(sliptack_config(normal_force="input"), channels=2)
    assert "input column 1" == est.normal_force_source_
    lo = est.predict(np.c_[x, np.full(len(x), 0.05)])
    hi = est.predict(np.c_[x, np.full(len(x), 0.10)])
    np.testing.assert_allclose(hi, 2.0 * lo, rtol=1e-12)
    X = np.c_[x, np.linspace(0.04, 0.06, len(x))]
    state = est.stream()
    rows = np.array([state.update(row) for row in X])
    np.testing.assert_array_equal(est.predict(X), rows[:, 1])


def test_input_normal_force_needs_the_second_column() -> None:
    """normal_force=input with one column is refused, naming both channels."""
    with pytest.raises(ValueError, match="the nib signal and the normal force"):
        sliptack_config(normal_force="input").fit(np.zeros((5, 1)), np.zeros(5))


@pytest.mark.parametrize(("source", "bound"), [("input", 2.0), ("value", None)])
def test_speed_task_with_per_trial_forces(
    tmp_path: Path, source: str, bound: float | None
) -> None:
    """Per-trial normal forces 0.03-0.08 N: the fed force keeps wood within 2 %; a fixed one does not."""
    import json

    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from slipkit import config_dir
    from slipkit.train.commands import train_main

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="train",
            overrides=[
                "experiment=sliptack_speed",
                f"run_dir={tmp_path / 'run'}",
                "dataset.n_trials=8",
                "scene.model.duration_s=1.2",
                "scene.model.materials=[basswood]",
                "scene.model.normal_force_N=[0.03,0.08]",
                "detector.window=500",
                "detector.hop=50",
                f"detector.normal_force={source}",
            ],
        )
    GlobalHydra.instance().clear()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FixedNormalForceWarning)
        train_main(cfg)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    err = metrics["test"]["basswood"]["mean_rel_err_pct"]
    if bound is None:
        assert err > 5.0
    else:
        assert err <= bound


# -- edge cases (Hypothesis) --------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(
    steps=arrays(np.float64, st.integers(0, 400), elements=st.floats(-0.05, 0.05)),
    nan_at=st.lists(st.integers(0, 399), max_size=5),
    k=st.integers(1, 3),
    polarity=st.sampled_from(["falling", "rising", "per_recording"]),
)
def test_confirmed_and_per_recording_batch_equals_stream_on_any_signal(
    steps: np.ndarray, nan_at: list[int], k: int, polarity: str
) -> None:
    """Random walks with NaN samples: batch scores equal the streaming replay for every rule."""
    v = np.r_[np.full(10, 4.5), 4.5 + np.cumsum(steps) * 20.0][:, None]
    v[[i for i in nan_at if i < len(v)]] = np.nan
    det = FSRTouchSlip(
        threshold=1.0,
        polarity=polarity,
        confirm_events=k,
        confirm_window_s=0.02,
        peak_gap_s=0.005,
    ).fit(np.full((20, 1), 4.5), np.zeros(20, int))
    scores, dec = det.replay(v)
    batch = det.decision_function(v)
    np.testing.assert_array_equal(batch, scores)
    assert (batch >= 1.0).tolist() == dec.tolist()


@settings(max_examples=60, deadline=None)
@given(mag=arrays(np.float64, st.integers(3, 30), elements=st.floats(0.0, 1e6)))
def test_parabolic_offset_is_bounded_and_finite(mag: np.ndarray) -> None:
    """Zeros, flats and huge magnitudes: every offset is finite and within half a bin."""
    off = parabolic_offset(mag, np.arange(1, len(mag) - 1))
    assert np.isfinite(off).all()
    assert np.abs(off).max(initial=0.0) <= 0.5
