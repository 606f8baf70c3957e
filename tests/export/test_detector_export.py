"""Analytic detector graphs (FSR, force derivative, pressure vibration, torsional slip) vs the batch detectors."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.signal import butter, sosfilt, sosfilt_zi

from slipkit import config_dir
from slipkit.data import Dataset
from slipkit.export import ExportError, exporter_for
from slipkit.export.detectors import (
    NO_SCORE,
    DetectorGraph,
    check_detector_parity,
    detector_windows,
    graph_scores,
    steady_state_fir,
)
from slipkit.export.parity import onnx_session
from slipkit.export.registry import IR_VERSION
from slipkit.families.biotac.detectors import ForceDerivative, PressureVibration
from slipkit.families.biotac.export.detectors import (
    export_force_derivative,
    export_pressure_vibration,
    pressure_baseline,
)
from slipkit.families.fsr.export.touch_slip import export_fsr_touch_slip
from slipkit.families.fsr.touch_slip import FSRTouchSlip
from slipkit.families.sliptack.export.torsion import export_torsional_slip
from slipkit.families.sliptack.torsion import TorsionalSlipDetector
from slipkit.sim.commands import build_scene

Arr = np.ndarray


# -- simulated recordings (as tests/families/fsr/test_touch_slip.py and tests/families/biotac/test_detectors.py) --
@lru_cache(maxsize=4)
def simulated(scene: str, n: int, seed: int) -> Dataset:
    """``n`` trials of ``scene`` from its real config."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={scene}"])
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    return build_scene(cfg.scene).simulate(n, seed=seed)


def fsr_data(seed: int, n: int = 3) -> tuple[Arr, Arr, Arr]:
    """(voltage X, slip_event labels, segments) of fsr_probe_slide trials."""
    xs, ys, segs = [], [], []
    for k, tr in enumerate(simulated("fsr_probe_slide", n, seed)):
        xs.append(tr.streams["fsr"][["voltage"]].to_numpy())
        ys.append(tr.streams["truth_contact"]["slip_event"].to_numpy())
        segs.append(np.full(len(xs[-1]), k))
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(segs)


def biotac_data(seed: int, stream: str, channels: list[str]) -> tuple[Arr, Arr, Arr]:
    """(X, onset labels, segments) of one stream of 3 biotac_lift_slip trials."""
    xs, ys, segs = [], [], []
    for k, tr in enumerate(simulated("biotac_lift_slip", 3, seed)):
        df = tr.streams[stream]
        xs.append(df[channels].to_numpy())
        ys.append((df["t"].to_numpy() >= tr.labels["slip_onset_s"]).astype(int))
        segs.append(np.full(len(df), k))
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(segs)


def run(graph: DetectorGraph, windows: Arr, session: Any = None) -> Arr:
    """Raw graph scores (float64) of windows in the graph's input dtype and shape (NO_SCORE where the detector says -inf)."""
    sess = session if session is not None else onnx_session(graph)
    x = np.asarray(windows, dtype=np.dtype(graph.input_dtype))
    x = x.reshape(len(x), *(int(d) for d in graph.input_shape[1:]))
    out = sess.run([graph.score_output], {graph.input_name: x})
    return np.asarray(out[0], dtype=np.float64)


def assert_parity(report: dict[str, Any]) -> None:
    """The issue-6 rule, spelled out (a failure shows the report)."""
    assert True is report["passed"], report
    assert report["agreement"] >= 0.999, report
    assert True is report["disagreements_near_threshold"], report
    assert 0 == report["n_finite_mismatch"], report


# -- registry and contract ---------------------------------------------------------------
@pytest.mark.parametrize(
    ("cls", "fn"),
    [
        (FSRTouchSlip, export_fsr_touch_slip),
        (ForceDerivative, export_force_derivative),
        (PressureVibration, export_pressure_vibration),
        (TorsionalSlipDetector, export_torsional_slip),
    ],
)
def test_registry_finds_each_detector_exporter(cls: type, fn: Any) -> None:
    """exporter_for returns the detector module's exporter for each detector class."""
    assert fn is exporter_for(cls)


def fitted_detectors() -> list[tuple[Any, Arr]]:
    """Small fitted detectors and a recording for each (synthetic, fast)."""
    rng = np.random.default_rng(0)
    v = np.r_[np.full(20, 4.5), np.full(40, 2.5)] + rng.normal(0, 1e-3, 60)
    f = rng.normal(size=(30, 2))
    p = 2048 + rng.normal(0, 3, 400)
    s = np.sin(np.arange(1200) / 1000 * 2 * np.pi * 10) + rng.normal(0, 0.1, 1200)
    return [
        (FSRTouchSlip(threshold=8.0).fit(v[:, None], np.zeros(60, int)), v[:, None]),
        (ForceDerivative().fit(f, np.zeros(30, int)), f),
        (
            PressureVibration(baseline=3.0).fit(p[:, None], np.zeros(400, int)),
            p[:, None],
        ),
        (
            TorsionalSlipDetector(threshold=0.3).fit(s[:, None], np.zeros(1200, int)),
            s[:, None],
        ),
    ]


@pytest.mark.parametrize("opset", [17, 18])
def test_every_graph_meets_the_registry_contract_and_is_non_strict(opset: int) -> None:
    """float32 (batch, W, C) input (FSR: float64 (batch, W)), IR 10, the opset asked for, '>=' rule; batch 1 == batch n."""
    for det, X in fitted_detectors():
        graph = exporter_for(det)(det, opset=opset)
        assert isinstance(graph, DetectorGraph)
        assert IR_VERSION == graph.model.ir_version
        assert opset == graph.opset
        fsr = isinstance(det, FSRTouchSlip)
        shape = ("batch", graph.window) if fsr else ("batch", graph.window, X.shape[1])
        assert (shape, "float64" if fsr else "float32") == (
            graph.input_shape,
            graph.input_dtype,
        )
        decision = graph.describe()["decision"]
        assert False is decision["strict"]
        assert float(det.threshold_) == decision["threshold"]
        assert {"window": graph.window, "hop": graph.hop} == {
            k: graph.describe()["frame"][k] for k in ("window", "hop")
        }
        windows, _ = detector_windows(graph, X)
        sess = onnx_session(graph)
        many = run(graph, windows, sess)
        one = np.concatenate([run(graph, w[None], sess) for w in windows[:5]])
        np.testing.assert_array_equal(many[:5], one)


def test_non_strict_rule_fires_at_exactly_the_threshold() -> None:
    """A force fall of exactly threshold_ N/s is slip for the detector and the exported rule."""
    det = ForceDerivative(threshold=100.0).fit(np.zeros((5, 1)), np.zeros(5, int))
    graph = export_force_derivative(det)
    window = np.array(
        [[3.0], [2.5], [2.25], [2.0]]
    )  # -dFt/dt = 1 N * 300 / 3 = 100 N/s
    score = run(graph, window[None])[0]
    assert 100.0 == score
    assert 1 == det.predict(window)[-1]
    assert score >= graph.decision()["threshold"]  # type: ignore[index]


# -- FSR ----------------------------------------------------------------------------------
@pytest.mark.parametrize("input_", ["voltage", "force"])
def test_fsr_graph_agrees_with_the_detector_on_simulated_recordings(
    input_: str,
) -> None:
    """Block-end decisions agree on >= 99.9 %; flips only where the fixed rest moves the gate."""
    X, y, seg = fsr_data(3)
    det = FSRTouchSlip(input=input_).fit(X, y, segments=seg)
    Xh, _, segh = fsr_data(4, n=2)
    report = check_detector_parity(det, export_fsr_touch_slip(det), Xh, segments=segh)
    assert_parity(report)
    assert report["max_rel_diff"] <= 1e-5
    assert (
        report["gate_eps"] <= 2e-3
    )  # V (N): recordings' rest means vs the graph's 4.5 V


def test_fsr_graph_with_the_recording_rest_equals_the_detector() -> None:
    """Given a recording's own rest mean, every block-end score equals the detector's."""
    X, y, seg = fsr_data(3)
    det = FSRTouchSlip().fit(X, y, segments=seg)
    x = X[seg == 0]
    graph = export_fsr_touch_slip(det, rest=float(np.mean(x[:10])))
    windows, inst = detector_windows(graph, x)
    ours, ref = graph_scores(run(graph, windows)), det.decision_function(x)[inst]
    np.testing.assert_array_equal(np.isfinite(ref), np.isfinite(ours))
    np.testing.assert_allclose(ref, ours, rtol=1e-5, atol=1e-3)  # V/s; alpha ~ 3-8
    assert ((ref >= det.threshold_) == (ours >= det.threshold_)).all()


def test_ungated_fsr_graph_agrees_with_the_gated_detector_on_touched_stretches() -> (
    None
):
    """gate=False: equal decisions wherever the detector is touched; it differs only untouched."""
    X, y, seg = fsr_data(3)
    det = FSRTouchSlip().fit(X, y, segments=seg)
    graph = export_fsr_touch_slip(det, gate=False)
    assert False is graph.features["gate"]  # type: ignore[index]
    n_touched, n_untouched_finite = 0, 0
    for k in range(3):
        x = X[seg == k]
        windows, inst = detector_windows(graph, x)
        ours, ref = graph_scores(run(graph, windows)), det.decision_function(x)[inst]
        touched = det.touch(x)[inst]
        flip = (ref >= det.threshold_) != (ours >= det.threshold_)
        # ROC thresholds are calibration scores: float32 input may flip those exactly at it
        assert (np.abs(ref - det.threshold_) <= 1e-3)[flip & touched].all()
        np.testing.assert_allclose(ref[touched], ours[touched], rtol=1e-5, atol=1e-3)
        n_touched += int(touched.sum())
        n_untouched_finite += int(np.isfinite(ours[~touched]).sum())
    assert n_touched > 1000
    assert n_untouched_finite > 0  # the gate is really out


def test_fsr_runtime_hop_of_five_lands_on_the_detector_block_ends(
    tmp_path: Path,
) -> None:
    """StreamLoop (window 10, hop 5) decides at samples 9, 14, 19, ...; from 14 on as predict."""
    from slipkit.runtime import StreamLoop, load_bundle, write_bundle

    X, y, seg = fsr_data(3)
    det = FSRTouchSlip().fit(X, y, segments=seg)
    graph = export_fsr_touch_slip(det)
    x = X[seg == 1]
    decision = {**graph.decision(), "positive": "1"}  # type: ignore[dict-item]
    del decision["threshold"]  # the manifest keeps it at the top level
    manifest = {
        "name": "fsr_detector",
        "frame": {
            "streams": ["fsr"],
            "channels": ["voltage"],
            "shape": [1],
            "window": graph.window,
            "hop": graph.hop,
            "rate_hz": 2000.0,
        },
        "preprocessing": [dict(s) for s in graph.preprocessing],  # press_sign
        "inputs": [{"name": graph.input_name, "dtype": "float64", "shape": [1, 10]}],
        "outputs": [{"name": "score", "dtype": "float64"}],
        "decision": decision,
        "threshold": graph.threshold,
        "debounce": {"k": 1},
        "budget_ms": {"frame_period": 0.5, "p99": 0.05},
        "opset": graph.opset,
        "producer": graph.producers,
    }
    path = write_bundle(tmp_path / "fsr", graph.serialize(), manifest)
    loop = StreamLoop(load_bundle(path))
    for i, row in enumerate(x.astype(np.float32)):
        loop.step(row, i / 2000.0)
    result = loop.result()
    assert [9, 14, 19] == result.frame[:3].tolist()
    later = result.frame >= graph.first_decision
    assert 14 == graph.first_decision
    assert graph.instants(len(x)).tolist() == result.frame[later].tolist()
    pred = det.predict(x).astype(bool)
    assert pred[result.frame[later]].tolist() == result.slip[later].tolist()


VOLT = st.floats(0.0, 5.0, width=32)


@settings(max_examples=60, deadline=None)
@given(
    window=arrays(np.float32, 10, elements=VOLT | st.just(np.nan) | st.just(np.inf)),
    input_=st.sampled_from(["voltage", "force"]),
)
def test_fsr_graph_equals_the_detector_after_a_rest_period(
    window: Arr, input_: str
) -> None:
    """Graph(window) == detector score at the window's end after 10 rest samples; NaN/inf: NO_SCORE or NaN, never a finite score."""
    det = FSRTouchSlip(input=input_, threshold=8.0, polarity="falling").fit(
        np.full((20, 1), 4.5), np.zeros(20, int)
    )
    graph = _fsr_graph(input_)
    rec = np.r_[np.full(10, 4.5), window.astype(np.float64)][:, None]
    with np.errstate(invalid="ignore", over="ignore"):  # inf samples, as intended
        ref = det.decision_function(rec)[19]
    ours = run(graph, window[None, :, None])[0]
    if not np.isfinite(window).all():
        # a non-finite sample in either block: no decision (the loop skips NaN)
        assert True is bool(NO_SCORE == ours or np.isnan(ours))
    elif np.isneginf(ref):
        assert NO_SCORE == ours
    else:
        # float64 in and out: only the summation order differs from numpy's means
        assert ours == pytest.approx(ref, rel=1e-9, abs=1e-9)


@lru_cache(maxsize=2)
def _fsr_graph(input_: str) -> DetectorGraph:
    det = FSRTouchSlip(input=input_, threshold=8.0, polarity="falling").fit(
        np.full((20, 1), 4.5), np.zeros(20, int)
    )
    return export_fsr_touch_slip(det, rest=4.5)


@settings(max_examples=30, deadline=None)
@given(level=VOLT)
def test_fsr_constant_window_scores_zero_when_touched(level: float) -> None:
    """A constant window has zero derivative: 0 when pressed below rest - delta, else NO_SCORE."""
    ours = run(_fsr_graph("voltage"), np.full((1, 10, 1), level, np.float32))[0]
    assert (0.0 if 4.5 - level > 0.2 else NO_SCORE) == ours


# -- force derivative -------------------------------------------------------------------
@pytest.mark.parametrize("channels", [["fx", "fy"], ["ft"]])
def test_force_derivative_graph_agrees_on_simulated_recordings(
    channels: list[str],
) -> None:
    """(Fx, Fy) or Ft: decisions agree on every held-out sample, scores to 1e-5 relative."""
    X, y, seg = biotac_data(5, "truth_force", channels)
    for thr in (None, 0.5):
        det = ForceDerivative(threshold=thr).fit(X, y, segments=seg)
        Xh, _, segh = biotac_data(6, "truth_force", channels)
        report = check_detector_parity(
            det, export_force_derivative(det), Xh, segments=segh
        )
        assert_parity(report)
        assert 1.0 == report["agreement"]
        assert report["max_rel_diff"] <= 1e-5


FORCE = st.floats(-1e4, 1e4, width=32) | st.sampled_from([np.nan, np.inf, -np.inf])


@settings(max_examples=80, deadline=None)
@given(window=arrays(np.float32, (4, 2), elements=FORCE))
def test_force_derivative_graph_equals_the_detector_on_any_window(window: Arr) -> None:
    """Window as a recording: same -dFt/dt; NO_SCORE iff an end is not finite (middle ignored)."""
    det, graph = _fd()
    with np.errstate(invalid="ignore"):  # inf - inf: a missing end, as intended
        ref = det.decision_function(window.astype(np.float64))[-1]
    ours = run(graph, window[None])[0]
    ends_finite = np.isfinite(window[[0, -1]]).all()
    assert ends_finite == (NO_SCORE != ours)
    if ends_finite:
        ft = np.hypot(*window[[0, -1]].astype(np.float64).T)
        assert ours == pytest.approx(ref, rel=1e-6, abs=1e-9 * 100 * max(ft.max(), 1.0))
    else:
        assert -np.inf == ref
        assert NO_SCORE == ours


@lru_cache(maxsize=1)
def _fd() -> tuple[ForceDerivative, DetectorGraph]:
    det = ForceDerivative().fit(np.zeros((5, 2)), np.zeros(5, int))
    return det, export_force_derivative(det)


# -- pressure vibration -----------------------------------------------------------------
def test_steady_state_fir_is_the_filter_from_the_window_start_with_the_stated_tail() -> (
    None
):
    """x @ M == sosfilt from the first sample's steady state; L is the shortest with T(L) <= tol."""
    sos = PressureVibration()._design()
    m, tail = steady_state_fir(sos, 22, tail_tol=1e-5)
    w = m.shape[0]
    h = np.abs(sosfilt(sos, np.r_[1.0, np.zeros(1 << 14)]))
    t = np.cumsum(h[::-1])[::-1]
    taps = w - 21
    assert t[taps] == pytest.approx(tail)
    assert t[taps] <= 1e-5 < t[taps - 1]
    assert 224 == w
    x = np.asarray(np.random.default_rng(1).normal(2048.0, 30.0, w))
    y, _ = sosfilt(sos, x, zi=sosfilt_zi(sos) * x[0])
    ref = np.asarray(y)[-22:]
    np.testing.assert_allclose(ref, x @ m, rtol=0, atol=1e-9)


def _pv_fit(threshold: float | None) -> tuple[PressureVibration, float]:
    X, y, seg = biotac_data(5, "pac", ["pac"])
    base = pressure_baseline(PressureVibration(), X, segments=seg)
    return PressureVibration(baseline=base, threshold=threshold).fit(
        X, y, segments=seg
    ), base


@pytest.mark.parametrize("threshold", [2.0, None])
def test_pressure_graph_agrees_on_simulated_recordings(threshold: float | None) -> None:
    """Fixed calibration baseline: decisions agree; score error within the tail bound."""
    det, base = _pv_fit(threshold)
    Xh, _, segh = biotac_data(6, "pac", ["pac"])
    graph = export_pressure_vibration(det)
    report = check_detector_parity(det, graph, Xh, segments=segh)
    assert_parity(report)
    # |filter error| <= T(L) x (largest deviation from a window's first sample)
    swing = max(np.ptp(Xh[segh == k]) for k in range(3))
    bound = graph.features["tail"] * swing / base  # type: ignore[index]
    assert report["max_abs_diff"] <= bound + 1e-9
    assert report["max_abs_diff"] > 0.0  # the truncation is real, and measured


def test_pressure_export_needs_a_fixed_baseline() -> None:
    """baseline=None (per recording) is refused with a message naming the option."""
    X = 2048 + np.random.default_rng(0).normal(0, 3, (400, 1))
    det = PressureVibration().fit(X, np.zeros(400, int))
    with pytest.raises(ExportError, match="baseline"):
        export_pressure_vibration(det)
    assert 5.0 == export_pressure_vibration(det, baseline=5.0).features["baseline"]  # type: ignore[index]


@lru_cache(maxsize=1)
def _pv() -> tuple[PressureVibration, DetectorGraph]:
    det = PressureVibration(baseline=4.0).fit(
        np.full((30, 1), 2048.0), np.zeros(30, int)
    )
    return det, export_pressure_vibration(det)


COUNTS = st.floats(1800, 2300, width=32)


@settings(max_examples=40, deadline=None)
@given(
    data=st.data(),
    amp=st.floats(0.0, 200.0),
)
def test_pressure_graph_equals_the_detector_on_a_window_as_recording(
    data: Any, amp: float
) -> None:
    """Window as a whole recording: the graph reproduces the batch score (same filter start)."""
    det, graph = _pv()
    w = graph.window
    seed = data.draw(st.integers(0, 2**16))
    x = np.round(2048 + amp * np.random.default_rng(seed).standard_normal(w)).astype(
        np.float32
    )
    ref = det.decision_function(x[:, None].astype(np.float64))[-1]
    ours = run(graph, x[None, :, None])[0]
    assert ours == pytest.approx(ref, rel=1e-7, abs=1e-9 * max(amp, 1.0))


@settings(max_examples=30, deadline=None)
@given(level=COUNTS, where=st.integers(0, 223), bad=st.sampled_from([np.nan, np.inf]))
def test_pressure_constant_window_scores_zero_and_a_missing_sample_scores_no_score(
    level: float, where: int, bad: float
) -> None:
    """A constant window scores ~0 (no vibration); one NaN/inf anywhere in it: NO_SCORE."""
    _, graph = _pv()
    x = np.full((1, graph.window, 1), level, np.float32)
    assert abs(run(graph, x)[0]) <= 1e-9
    x[0, where, 0] = bad
    assert NO_SCORE == run(graph, x)[0]


# -- SlipTack torsional slip --------------------------------------------------------------
def _torsion_recording(seed: int) -> tuple[Arr, Arr]:
    """Nib signal (mm, 1 kHz) on a 2 mm offset: noise, then a 10 Hz torsional burst."""
    rng = np.random.default_rng(seed)
    t = np.arange(4000) / 1000.0
    x = 2.0 + 0.3 * t + rng.normal(0, 0.02, len(t))
    on = (t >= 2.0) & (t < 3.0)
    x[on] += 0.2 * np.sin(2 * np.pi * 10 * t[on])
    return x[:, None], on.astype(int)


def test_torsional_graph_agrees_with_the_detector_after_its_start_transient() -> None:
    """Steady-state windowed band-pass + RMS: decisions agree from sample W - 1 on."""
    X, y = _torsion_recording(0)
    det = TorsionalSlipDetector().fit(X, y)
    graph = export_torsional_slip(det)
    Xh, _ = _torsion_recording(1)
    report = check_detector_parity(det, graph, Xh)
    assert_parity(report)
    assert report["max_rel_diff"] <= 1e-3


def test_torsional_graph_reads_nan_as_zero_like_the_detector() -> None:
    """NaN samples are zero deflection in the graph, as numpy.nan_to_num makes them."""
    X, y = _torsion_recording(0)
    det = TorsionalSlipDetector(threshold=0.05).fit(X, y)
    graph = export_torsional_slip(det)
    w = X[-graph.window :, 0].astype(np.float32).copy()
    w[[5, 500]] = np.nan
    zero = np.nan_to_num(w)
    np.testing.assert_array_equal(
        run(graph, zero[None, :, None]), run(graph, w[None, :, None])
    )


def test_band_matrix_matches_a_butterworth_designed_here() -> None:
    """The torsional graph's window follows from the stated tail (5-15 Hz at 1 kHz, 1e-5)."""
    sos = butter(2, [5.0, 15.0], btype="bandpass", fs=1000.0, output="sos")
    m, tail = steady_state_fir(sos, 100, tail_tol=1e-5)
    det = TorsionalSlipDetector(threshold=0.1).fit(np.zeros((10, 1)), np.zeros(10, int))
    graph = export_torsional_slip(det)
    assert m.shape[0] == graph.window
    assert tail <= 1e-5
