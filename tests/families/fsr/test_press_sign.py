"""FSR detectors deploy with the stream's own rest level (issue 14): the runtime op
``press_sign`` takes each stream's rest level from its first samples, as the batch detector
does per recording, with a fixed polarity's sign or, per recording, the wiring sign latched
at its first press; the graph reads the sign-normalised signal."""

from __future__ import annotations

import functools
import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from omegaconf import DictConfig
from tests.baselines.test_conventions import ROBUST, fsr_trials, stack

from slipkit import config_dir
from slipkit.export.detectors import check_detector_parity
from slipkit.export.registry import ExportError
from slipkit.families.fsr.export.touch_slip import (
    export_fsr_touch_slip,
    fsr_press_sign_step,
)
from slipkit.families.fsr.touch_slip import FSRTouchSlip, PolarityWarning
from slipkit.runtime.errors import BundleError
from slipkit.runtime.preprocessing import Pipeline
from slipkit.runtime.sources import ReplaySource

FORMS = {"paper": {}, "robust": ROBUST}


def _mixed_detector(form: str, threshold: float | None) -> FSRTouchSlip:
    """Fitted on generated slides of both wirings: polarity auto becomes per_recording."""
    trials = fsr_trials(100, 3, polarity="falling", slide=True) + fsr_trials(
        101, 3, polarity="rising", slide=True
    )
    X, y, seg = stack(trials)
    det = FSRTouchSlip(threshold=threshold, **FORMS[form])  # type: ignore[arg-type]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PolarityWarning)
        return det.fit(X, y, segments=seg)


def _press_sign(window: int = 10, **params: object) -> Pipeline:
    step = {"op": "press_sign", "rest_frames": 10, "block": 5, "hop": 5, "delta": 0.2}
    return Pipeline([{**step, **params}], (window, 1), "manifest.json")


@pytest.mark.parametrize(("wiring", "sign"), [("falling", 1.0), ("rising", -1.0)])
def test_press_sign_latches_the_rest_and_the_sign_at_the_first_press(
    wiring: str, sign: float
) -> None:
    """Zeros until the first block mean 0.2 V from rest, then sign * (v - rest)."""
    v = np.full(40, 2.0)
    v[:10] = [2.0, 2.1] * 5  # rest mean 2.05 V
    press = -1.0 if wiring == "falling" else 1.0
    v[25:] = 2.05 + press * 0.5  # block 5 (samples 25-29) is the first one pressed
    pipe = _press_sign()
    outs = [pipe(v[end - 9 : end + 1][:, None])[:, 0].copy() for end in range(9, 40, 5)]
    assert [0.0] * 10 == outs[3].tolist()  # window ending at block 4: not pressed
    np.testing.assert_allclose(sign * (v[20:30] - 2.05), outs[4], atol=1e-12)
    np.testing.assert_allclose(sign * (v[30:40] - 2.05), outs[6], atol=1e-12)


def test_press_sign_never_latches_on_the_rest_blocks() -> None:
    """A transient inside the rest period (blocks 0-1) sets no sign; a later press does."""
    v = np.full(30, 3.0)
    v[:5], v[5:10] = 2.0, 4.0  # rest mean 3 V, both rest blocks 1 V from it
    v[20:] = 3.5  # block 4 rises 0.5 V: the rising wiring
    pipe = _press_sign()
    outs = [pipe(v[end - 9 : end + 1][:, None])[:, 0].copy() for end in range(9, 30, 5)]
    assert [0.0] * 10 == outs[2].tolist()
    np.testing.assert_allclose(-(v[15:25] - 3.0), outs[3], atol=1e-12)


def test_press_sign_reset_forgets_the_stream() -> None:
    """After reset the next window is a new stream's start (its own rest level)."""
    pipe = _press_sign()
    v = np.r_[np.full(10, 1.0), np.full(10, 0.5)]
    for end in (9, 14, 19):
        pipe(v[end - 9 : end + 1][:, None])
    pipe.ops[0].reset()  # type: ignore[attr-defined]
    assert [0.0] * 10 == pipe(np.full((10, 1), 0.5)).ravel().tolist()


@pytest.mark.parametrize(
    ("params", "field"),
    [({"hop": 3}, "hop"), ({"block": 4, "hop": 4}, "block"), ({"delta": 0}, "delta")],
)
def test_press_sign_refuses_parameters_naming_the_field(
    params: dict[str, object], field: str
) -> None:
    """A hop off the block grid, a block not dividing the window, delta <= 0: named."""
    with pytest.raises(BundleError, match=rf"preprocessing\[0\]\.{field}"):
        _press_sign(**params)


@pytest.mark.parametrize("form", sorted(FORMS))
@pytest.mark.parametrize("threshold", [8.0, None], ids=["alpha8", "roc"])
def test_per_recording_graph_through_press_sign_equals_the_detector_on_both_wirings(
    form: str, threshold: float | None
) -> None:
    """Paper and confirmed graphs after press_sign decide as the batch detector on
    generated slides and knocks of either wiring (each recording its own stream)."""
    det = _mixed_detector(form, threshold)
    graph = export_fsr_touch_slip(det)
    assert (fsr_press_sign_step(det),) == graph.preprocessing
    for wiring in ("falling", "rising"):
        held = fsr_trials(200, 2, polarity=wiring, slide=True) + fsr_trials(
            500, 2, polarity=wiring, slide=False
        )
        X, _, seg = stack(held)
        rep = check_detector_parity(det, graph, X, segments=seg)
        assert (True, 0) == (rep["passed"], rep["n_finite_mismatch"])
        assert rep["agreement"] >= 0.999
        scores = det.decision_function(X, segments=seg)
        assert bool(np.any(scores >= det.threshold_))  # the slides fire: not vacuous


@functools.cache
def _walk_detector(k: int) -> tuple[FSRTouchSlip, Any, Any]:
    """A per-recording detector (1 V/s; 20 ms confirmation), its graph and session."""
    from slipkit.export.parity import onnx_session

    det = FSRTouchSlip(
        threshold=1.0,
        polarity="per_recording",
        confirm_events=k,
        confirm_window_s=0.02,
        peak_gap_s=0.005,
    ).fit(np.full((20, 1), 2.5), np.zeros(20, int))
    graph = export_fsr_touch_slip(det)
    return det, graph, onnx_session(graph)


@settings(max_examples=30, deadline=None)
@given(
    steps=arrays(np.float64, st.integers(0, 300), elements=st.floats(-0.05, 0.05)),
    press=st.sampled_from([-1.0, 1.0]),
    nan_at=st.lists(st.integers(0, 299), max_size=4),
    k=st.sampled_from([1, 3]),
)
def test_press_sign_and_graph_equal_the_detector_on_any_walk(
    steps: np.ndarray, press: float, nan_at: list[int], k: int
) -> None:
    """Random walks after a rest, pressed either way, with NaN samples: the op + graph
    decide as the per-recording batch detector (differences only at float32 ties)."""
    v = np.r_[np.full(10, 2.5), 2.5 + press * 0.3 + np.cumsum(steps) * 20.0][:, None]
    v[[i for i in nan_at if i < len(v)]] = np.nan
    det, graph, sess = _walk_detector(k)
    if len(graph.instants(len(v))) == 0:
        return  # shorter than the first decision: nothing to compare
    rep = check_detector_parity(det, graph, v, session=sess)
    # every difference lies at a float32 tie with the threshold or the gate (a linear
    # ramp's equal derivatives can gain or lose a peak in float32; a last sample back
    # at the rest level flips the gate); "passed" also needs 99.9 % agreement, which a
    # walk of a few decisions cannot show with one tie
    assert True is rep["disagreements_near_threshold"]
    if rep["n_frames"] >= 1000:
        assert True is rep["passed"]


def test_a_release_at_the_last_sample_differs_only_at_the_gate() -> None:
    """A press held, then one sample back above the rest at the very end: the graph's
    gate and the batch detector's may differ there, and only there."""
    steps = np.zeros(25)
    steps[0], steps[-1] = 0.002, 0.015
    v = np.r_[np.full(10, 2.5), 2.5 - 0.3 + np.cumsum(steps) * 20.0][:, None]
    det, graph, sess = _walk_detector(1)
    rep = check_detector_parity(det, graph, v, session=sess)
    assert rep["n_disagree"] <= 1
    assert True is rep["disagreements_near_threshold"]


def test_per_recording_export_refuses_a_fixed_rest() -> None:
    """rest=... has no meaning when the stream sets the rest level: ExportError."""
    det = _mixed_detector("paper", 8.0)
    with pytest.raises(ExportError, match="press_sign"):
        export_fsr_touch_slip(det, rest=4.0)


def _compose(name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


@pytest.fixture(scope="module")
def hard_fsr(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(run, bundle) of fsr_robust trained on 6 trials of the hard scene (mixed
    wirings), exported without session choice."""
    from slipkit.export.commands import export_main
    from slipkit.train.commands import train_main

    tmp = tmp_path_factory.mktemp("hard_fsr")
    run_dir, out = tmp / "run", tmp / "bundle"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PolarityWarning)
        train_main(
            _compose(
                "train",
                [
                    "experiment=fsr_robust",
                    "scene=fsr_probe_slide_hard",
                    "dataset.n_trials=6",
                    f"run_dir={run_dir}",
                ],
            )
        )
        export_main(
            _compose("export", [f"run={run_dir}", f"out={out}", "choose_session=false"])
        )
    return run_dir, out


@pytest.mark.filterwarnings("ignore::slipkit.families.fsr.touch_slip.PolarityWarning")
def test_fsr_robust_bundle_on_the_hard_scene_decides_as_the_detector_per_stream(
    hard_fsr: tuple[Path, Path],
) -> None:
    """Trained on the hard scene's mixed wirings, exported, replayed per held-out trial
    through StreamLoop (reset between streams): decisions equal the batch detector's."""
    from slipkit.export.deploy import trial_frames
    from slipkit.runtime import StreamLoop, load_bundle
    from slipkit.train.data import training_dataset
    from slipkit.train.runs import read_run

    run_dir, out = hard_fsr
    run = read_run(run_dir)
    assert "per_recording" == run.model.polarity_
    raw = json.loads((out / "manifest.json").read_text())
    assert ["press_sign"] == [s["op"] for s in raw["preprocessing"]]
    loop = StreamLoop(load_bundle(out))
    thr = float(loop.bundle.manifest.decision.threshold or 0.0)
    test_ids = json.loads((run_dir / "metrics.json").read_text())["split"]["test"]
    data = training_dataset(run.config)
    wirings = set(
        data.trials.set_index("trial_id").loc[test_ids, "fsr_polarity.polarity"]
    )
    assert {"falling", "rising"} == wirings
    n_slip = 0
    for tr in trial_frames(data, test_ids, "fsr", ["voltage"]):
        loop.reset()
        for values in tr.frames:
            loop.step(values)
        res = loop.result()
        ref = run.model.decision_function(tr.frames)[res.frame]
        assert (ref >= thr).tolist() == res.slip.tolist()
        n_slip += int(res.slip.sum())
    assert n_slip > 0


@pytest.mark.filterwarnings("ignore::slipkit.families.fsr.touch_slip.PolarityWarning")
def test_fsr_hard_scene_export_checks_the_loop_over_a_stream_and_replays_each_wiring(
    hard_fsr: tuple[Path, Path],
) -> None:
    """The export ran the loop over every held-out trial as one stream with gaps
    (stream parity passed); the replay holds trials of both wirings a gap apart, and
    the bundle's loop over it decides as the detector on each trial."""
    from slipkit.export.deploy import trial_frames
    from slipkit.runtime import StreamLoop, load_bundle
    from slipkit.runtime.sources import load_replay
    from slipkit.train.data import training_dataset
    from slipkit.train.runs import read_run

    run_dir, out = hard_fsr
    raw = json.loads((out / "manifest.json").read_text())
    stream = raw["training"]["stream_parity"]
    assert (True, True, 0) == (
        stream["passed"],
        stream["calls_match"],
        stream["n_disagree"],
    )
    run = read_run(run_dir)
    data = training_dataset(run.config)
    test_ids = json.loads((run_dir / "metrics.json").read_text())["split"]["test"]
    held = trial_frames(data, test_ids, "fsr", ["voltage"])
    assert len(held) == stream["recordings"]
    bundle = load_bundle(out)
    frames, times = load_replay(out / "replay.npz", (1,), 2000.0)
    cuts = np.flatnonzero(np.diff(times) > 1.5 / bundle.manifest.frame.rate_hz) + 1
    parts = np.split(np.arange(len(frames)), cuts)
    assert raw["training"]["replay"]["trials"] == len(parts)
    wiring = data.trials.set_index("trial_id")["fsr_polarity.polarity"]
    seen = set()
    res = StreamLoop(bundle).run(ReplaySource(frames, times))
    thr = float(bundle.manifest.decision.threshold or 0.0)
    for idx in parts:
        (tr,) = [t for t in held if np.array_equal(t.frames, frames[idx])]
        seen.add(wiring.loc[tr.trial_id])
        mine = (res.frame >= idx[0]) & (res.frame <= idx[-1])
        ref = run.model.decision_function(tr.frames)[res.frame[mine] - idx[0]]
        assert (ref >= thr).tolist() == res.slip[mine].tolist()
    assert {"falling", "rising"} == seen


# -- a fixed polarity: the rest level from the stream, the sign from fit ---------------------
@pytest.mark.parametrize("sign", [1, -1])
def test_press_sign_with_a_fixed_sign_uses_it_from_the_rest_on(sign: int) -> None:
    """sign * (v - rest) as soon as the rest period has passed, before any press; a
    press of the other direction latches nothing; reset keeps the fixed sign."""
    v = np.full(30, 2.0)
    v[:10] = [2.0, 2.1] * 5  # rest mean 2.05 V
    v[20:] = 2.05 + sign * 0.5  # a press of the wiring opposite to `sign`
    pipe = _press_sign(sign=sign)
    outs = [pipe(v[end - 9 : end + 1][:, None])[:, 0].copy() for end in range(9, 30, 5)]
    for k, end in enumerate(range(9, 30, 5)):
        np.testing.assert_allclose(sign * (v[end - 9 : end + 1] - 2.05), outs[k])
    assert float(sign) == pipe.ops[0].sign  # type: ignore[attr-defined]
    pipe.ops[0].reset()  # type: ignore[attr-defined]
    np.testing.assert_allclose(
        np.zeros(10), pipe(np.full((10, 1), 0.5)).ravel(), atol=0.0
    )  # a new stream: its own rest (0.5 V), the same sign
    assert float(sign) == pipe.ops[0].sign  # type: ignore[attr-defined]


def test_press_sign_with_a_fixed_sign_and_no_finite_rest_gives_zeros() -> None:
    """No finite sample in the rest period: no rest level, zeros (never touched)."""
    v = np.r_[np.full(10, np.nan), np.full(10, 1.0)][:, None]
    pipe = _press_sign(sign=1)
    pipe(v[:10])
    assert [0.0] * 10 == pipe(v[5:15]).ravel().tolist()


@pytest.mark.parametrize("value", [2, 0.5, True])
def test_press_sign_refuses_a_sign_other_than_minus_one_zero_or_one(
    value: object,
) -> None:
    """sign 2, 0.5 or true: BundleError naming preprocessing[0].sign."""
    with pytest.raises(BundleError, match=r"preprocessing\[0\]\.sign"):
        _press_sign(sign=value)


def _one_wiring_detector(form: str, wiring: str) -> FSRTouchSlip:
    """Fitted (polarity auto, ROC alpha) on generated slides of one wiring only."""
    X, y, seg = stack(fsr_trials(100, 3, polarity=wiring, slide=True))
    det = FSRTouchSlip(**FORMS[form])  # type: ignore[arg-type]
    return det.fit(X, y, segments=seg)


OTHER = {"falling": "rising", "rising": "falling"}


@pytest.mark.parametrize("form", sorted(FORMS))
@pytest.mark.parametrize("wiring", ["falling", "rising"])
def test_fixed_polarity_graph_through_press_sign_equals_the_detector_on_both_wirings(
    form: str, wiring: str
) -> None:
    """Trained on one wiring (a fixed polarity), the graph after press_sign (the fitted
    sign, the stream's rest) passes parity on held-out slides and knocks of both
    wirings; on the other wiring neither side ever decides."""
    det = _one_wiring_detector(form, wiring)
    assert wiring == det.polarity_
    graph = export_fsr_touch_slip(det)
    step = fsr_press_sign_step(det)
    assert (1 if wiring == "falling" else -1) == step["sign"]
    assert (step,) == graph.preprocessing
    for held in (wiring, OTHER[wiring]):
        X, _, seg = stack(
            fsr_trials(200, 2, polarity=held, slide=True)
            + fsr_trials(500, 1, polarity=held, slide=False)
        )
        rep = check_detector_parity(det, graph, X, segments=seg)
        assert (True, 0) == (rep["passed"], rep["n_finite_mismatch"])
        fired = bool(np.any(det.decision_function(X, segments=seg) >= det.threshold_))
        assert (held == wiring) == fired  # the other wiring is never touched


def _bundle(graph: Any, path: Path) -> Path:
    """A bundle of an FSR detector graph with its preprocessing (window 10, hop 5)."""
    from slipkit.runtime import write_bundle

    decision = {**graph.decision(), "positive": "1"}
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
        "preprocessing": [dict(s) for s in graph.preprocessing],
        "inputs": [
            {
                "name": graph.input_name,
                "dtype": graph.input_dtype,  # float64: the graph reads the window as is
                "shape": [1, *graph.input_shape[1:]],
            }
        ],
        "outputs": [{"name": "score", "dtype": "float64"}],
        "decision": decision,
        "threshold": graph.threshold,
        "debounce": {"k": 1},
        "budget_ms": {"frame_period": 0.5, "p99": 0.05},
        "opset": graph.opset,
        "producer": graph.producers,
    }
    return write_bundle(path, graph.serialize(), manifest)


def test_fixed_polarity_bundle_decides_as_the_detector_on_a_recording_of_the_other_wiring(
    tmp_path: Path,
) -> None:
    """Trained on the falling wiring: the bundle, replayed per held-out recording through
    StreamLoop, decides as the batch detector on both wirings; a graph with a fixed
    rest constant instead fires on the rising wiring, where the detector never does."""
    from slipkit.export.detectors import detector_windows, graph_scores
    from slipkit.export.parity import onnx_session
    from slipkit.runtime import StreamLoop, load_bundle

    det = _one_wiring_detector("paper", "falling")
    graph = export_fsr_touch_slip(det)
    loop = StreamLoop(load_bundle(_bundle(graph, tmp_path / "fsr")))
    fixed = export_fsr_touch_slip(det, rest=det.rest_V_)  # the graph before issue 14
    fixed_sess = onnx_session(fixed)
    n_slip = {"falling": 0, "rising": 0}
    for wiring in ("falling", "rising"):
        for tr in fsr_trials(200, 2, polarity=wiring, slide=True):
            x = tr.v[:, None]
            loop.reset()
            for row in x.astype(np.float32):
                loop.step(row)
            res = loop.result()
            later = res.frame >= graph.first_decision
            ref = det.decision_function(x)[res.frame[later]]
            assert (ref >= det.threshold_).tolist() == res.slip[later].tolist()
            n_slip[wiring] += int(res.slip.sum())
            if wiring == "rising":
                assert bool(np.all(np.isneginf(det.decision_function(x))))
                windows, _ = detector_windows(fixed, x)
                out = fixed_sess.run([fixed.score_output], {fixed.input_name: windows})
                assert bool(np.any(graph_scores(out[0]) >= det.threshold_))
    assert 0 < n_slip["falling"]
    assert 0 == n_slip["rising"]


def test_fsr_comparison_of_four_trials_exports_every_estimator(tmp_path: Path) -> None:
    """slipkit compare comparison=fsr with 4 trials (the demo's size; the 2 training
    trials have one wiring, a held-out one the other): all six estimators export."""
    import pandas as pd

    from slipkit.compare.commands import compare_main
    from slipkit.train.runs import read_run

    out = tmp_path / "fsr"
    cfg = _compose(
        "compare",
        [
            "comparison=fsr",
            "comparison.dataset.n_trials=4",
            "seeds=[0]",
            f"out={out}",
            "progress=false",
            "cost.max_frames=200",
        ],
    )
    compare_main(cfg)
    df = pd.read_csv(out / "metrics.csv")
    assert [
        "fsr_roc",
        "fsr_paper",
        "fsr_robust",
        "window_logreg",
        "fsr_onset",
        "fsr_onset_logistic",
    ] == df["estimator"].tolist()
    assert ["ok"] * 6 == df["export"].tolist()
    assert "falling" == read_run(out / "runs" / "fsr_paper").model.polarity_


def _tied_slide() -> tuple[FSRTouchSlip, np.ndarray, np.ndarray]:
    """A confirmed detector (2 peaks within 30 ms) and a pressed staircase on a binary
    voltage grid (exact in float32) whose blocks 6 and 7 rise by the same step (a tie,
    as an ADC gives), and the same staircase with block 7 raised 0.2 uV (float32
    rounding of a sign-normalised sample)."""
    inc = np.zeros(40)
    inc[[6, 7]], inc[12] = 4.0, 8.0  # per block, in 2^-10 V steps: a tie, a larger peak
    v = np.r_[np.full(10, 4.5), np.repeat(4.0 + np.cumsum(inc) * 2.0**-10, 5)]
    rounded = v.copy()
    rounded[10 + 7 * 5 : 10 + 8 * 5] += 2e-7
    det = FSRTouchSlip(
        threshold=1.0,
        polarity="falling",
        confirm_events=2,
        confirm_window_s=0.03,
        peak_gap_s=0.005,
    ).fit(v[:, None], np.zeros(len(v), int))
    return det, v[:, None], rounded[:, None]


def test_confirmed_score_ignores_float32_rounding_at_a_derivative_tie() -> None:
    """Two equal block derivatives stay a tie (the first is the peak) when rounding
    moves one by 1e-4 V/s, so the peak does not move a block (closed-loop fsr_robust:
    scores 0.195 apart, parity 98.9 %)."""
    det, exact, rounded = _tied_slide()
    expected = det.decision_function(exact)
    assert bool(np.any(expected >= det.threshold_))  # the tie's peak is counted
    np.testing.assert_array_equal(expected, det.decision_function(rounded))


def test_confirmed_graph_reads_a_rounded_tie_as_the_detector() -> None:
    """The graph's peak test treats near-equal derivatives as the detector does:
    parity passes on the rounded staircase with scores equal to float32 precision."""
    det, _, rounded = _tied_slide()
    rep = check_detector_parity(det, export_fsr_touch_slip(det), rounded)
    assert (True, 0) == (rep["passed"], rep["n_finite_mismatch"])
    assert rep["max_abs_diff"] < 1e-3


@pytest.mark.parametrize("on_score", [True, False])
def test_alpha_on_a_training_score_moves_halfway_to_the_next_lower(
    on_score: bool,
) -> None:
    """A threshold equal to a training score (a ROC choice) moves halfway down to the
    next lower score, so repeated scores of a quantised signal never sit on it; any
    other threshold is kept."""
    det, exact, _ = _tied_slide()
    scores = det.decision_function(exact)
    finite = np.unique(scores[np.isfinite(scores)])
    top, below = float(finite[-1]), float(finite[-2])
    given = top if on_score else 0.5 * (top + below) + 0.01
    det.set_params(threshold=given).fit(exact, np.zeros(len(exact), int))
    expected = 0.5 * (top + below) if on_score else given
    assert expected == det.threshold_


def _stream_with_gaps(
    trials: list[Any], rate_hz: float, gap_periods: float = 10.0
) -> tuple[np.ndarray, np.ndarray]:
    """The trials end to end as one stream (frames, timestamps), ``gap_periods``
    frame periods between one trial's last frame and the next's first."""
    frames, times, start = [], [], 0.0
    for tr in trials:
        t = start + np.arange(len(tr.v)) / rate_hz
        frames.append(tr.v[:, None])
        times.append(t)
        start = float(t[-1]) + gap_periods / rate_hz
    return np.concatenate(frames), np.concatenate(times)


def test_mixed_wiring_bundle_decides_as_the_detector_over_one_stream_with_gaps(
    tmp_path: Path,
) -> None:
    """A per-recording (mixed-wiring) bundle fed four trials of alternating wiring as
    one stream, a gap between trials: each gap starts a new recording (press_sign
    reset, window and hop grid restarted), so the loop decides on exactly the
    detector's instants of each trial, with the detector's decisions."""
    from slipkit.runtime import StreamLoop, load_bundle

    det = _mixed_detector("paper", 8.0)
    graph = export_fsr_touch_slip(det)
    trials = []
    for seed in (200, 201):
        trials += fsr_trials(seed, 1, polarity="falling", slide=True)
        trials += fsr_trials(seed, 1, polarity="rising", slide=True)
    rate = 2000.0
    x, t = _stream_with_gaps(trials, rate)
    loop = StreamLoop(load_bundle(_bundle(graph, tmp_path / "fsr")), capacity=4096)
    res = loop.run(ReplaySource(x, t))
    starts = np.r_[0, np.cumsum([len(tr.v) for tr in trials])]
    expected_frames, expected_slip = [], []
    for k, tr in enumerate(trials):
        inst = np.arange(graph.window - 1, len(tr.v), graph.hop)  # each trial's grid
        ref = det.decision_function(tr.v[:, None])[inst]
        expected_frames += (starts[k] + inst).tolist()
        expected_slip += (ref >= det.threshold_).tolist()
    assert 3 == res.gaps
    assert expected_frames == res.frame.tolist()
    assert expected_slip == res.slip.tolist()
    assert 0 < sum(expected_slip)  # the slides fire: not vacuous
