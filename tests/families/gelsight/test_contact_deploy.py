"""The deployed contact detector: batch, streaming, the runtime step and the ONNX graph agree."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slipkit.families.gelsight.detectors import PinMotionDetector
from slipkit.families.gelsight.features import pitch_of, to_points
from slipkit.families.gelsight.stream import PinContactDetector
from slipkit.runtime.errors import BundleError
from slipkit.runtime.ops.gelsight import marker_pitch
from slipkit.runtime.preprocessing import Pipeline


def _field(scale: np.ndarray, shift: np.ndarray, seed: int = 0) -> np.ndarray:
    """A 5x5 pin grid (pitch 30 px, origin 300 px) scaled about its centre by
    ``scale[t]``, moved along x by ``shift[t]``, plus 0.03 px noise: ``x_*`` then ``y_*``."""
    xs, ys = np.meshgrid(300 + np.arange(5) * 30.0, 200 + np.arange(5) * 30.0)
    p = np.column_stack([xs.ravel(), ys.ravel()])
    c = p.mean(axis=0)
    pts = c + (p - c)[None] * scale[:, None, None]
    pts[..., 0] += shift[:, None]
    f = np.concatenate([pts[..., 0], pts[..., 1]], axis=1)
    return f + np.random.default_rng(seed).normal(0, 0.03, f.shape)


def _recordings() -> tuple[np.ndarray, np.ndarray]:
    """Three recordings: a contraction at frames 4-8, a late shake, a slow spread."""
    t = np.arange(120, dtype=np.float64)
    slip = _field(1 - 0.02 * np.clip((t - 4) / 4, 0, 1), np.zeros(len(t)), 1)
    on = t >= 60
    wiggle = _field(1 + on * 0.05 * np.sin(t / 3), on * 5.0 * np.sin(t / 3), 2)
    spread = _field(1 + 0.0005 * t, 0.1 * t, 3)
    X = np.concatenate([slip, wiggle, spread])
    seg = np.repeat([0, 1, 2], len(t))
    return X, seg


@pytest.mark.parametrize(
    ("quantity", "horizon"),
    [("divergence_per_path", 40), ("contraction", None), ("divergence", 80)],
)
def test_scores_as_the_reports_contact_motion_and_streams_alike(
    quantity: str, horizon: int | None
) -> None:
    X, seg = _recordings()
    det = PinContactDetector(quantity=quantity, horizon=horizon, threshold=0.01)
    det.fit(X, np.zeros(len(X), int), segments=seg)
    s = det.decision_function(X, segments=seg)
    report = PinMotionDetector(
        quantity=quantity, window=50, arm=3, horizon=horizon
    ).frame_scores({"camera_0": X[seg == 0]})
    if quantity == "divergence_per_path":
        np.testing.assert_allclose(
            s[seg == 0], np.where(np.isfinite(report), report, -np.inf)
        )
    first = s[seg == 0]
    assert np.isneginf(first[:7]).all()
    assert np.isfinite(first[7])
    if horizon is not None:
        assert np.isneginf(first[3 + horizon :]).all()
        assert np.isfinite(first[3 + horizon - 1])
    for k in range(3):
        stream = det.stream()
        got = np.array([stream.update(x)[0] for x in X[seg == k]])
        np.testing.assert_allclose(got, s[seg == k], rtol=1e-12)


def _two_fingertips() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Both fingertips side by side (the second sees the recordings in another order,
    its pins of the third recording all lost), each fingertip alone, and the segments."""
    X, seg = _recordings()
    n = int((seg == 0).sum())
    other = np.roll(X, n, axis=0)
    other[seg == 2] = np.nan
    return np.hstack([X, other]), X, other, seg


def test_two_fingertips_score_the_larger_of_their_own_scores() -> None:
    both, a, b, seg = _two_fingertips()
    one = PinContactDetector(horizon=60, threshold=0.01)
    two = PinContactDetector(horizon=60, threshold=0.01, fingertips=2)
    two.fit(both, np.zeros(len(both), int), segments=seg)
    s = two.decision_function(both, segments=seg)
    alone = [
        one.fit(x, np.zeros(len(x), int), segments=seg).decision_function(
            x, segments=seg
        )
        for x in (a, b)
    ]
    np.testing.assert_array_equal(s, np.maximum(*alone))
    assert np.isneginf(alone[1][seg == 2]).all()  # no pins: the first fingertip decides
    np.testing.assert_array_equal(s[seg == 2], alone[0][seg == 2])
    for k in range(3):
        stream = two.stream()
        got = np.array([stream.update(x)[0] for x in both[seg == k]])
        np.testing.assert_allclose(got, s[seg == k], rtol=1e-12)
    with pytest.raises(ValueError, match="2 fingertip"):
        two.fit(a[:, :50], np.zeros(len(a), int), segments=seg)


def test_runtime_pitch_is_the_features_pitch() -> None:
    X, _ = _recordings()
    for row in X[[0, 130, 300]]:
        assert marker_pitch(row) == pytest.approx(pitch_of(to_points(row[None])[0]))
    row = X[0].copy()
    row[1:25] = np.nan
    row[26:] = np.nan
    assert np.isnan(marker_pitch(row))


def test_contact_window_holds_the_reference_then_slides_and_resets() -> None:
    X, _ = _recordings()
    x = X[:120]
    w, arm = 10, 3
    step = {"op": "contact_window", "arm": arm, "window": w, "min_frames": 4}
    pipe = Pipeline([{**step, "horizon": 30}], (1, 50), "test")
    outs = [pipe(x[t : t + 1]).copy() for t in range(len(x))]
    assert all(o.shape == (w + 1, 50) for o in outs)
    # not deciding before arm + min_frames - 1 and from arm + horizon on
    decide = np.array([o[w, 0] for o in outs])
    assert (decide[: arm + 3] == 0).all()
    assert (decide[arm + 3 : arm + 30] == 1).all()
    assert (decide[arm + 30 :] == 0).all()
    pitch = marker_pitch(x[arm])
    # frame 8: 6 armed frames, front-padded with the first armed frame
    o = outs[8][:w]
    ref = x[arm]
    centre = np.repeat([ref[:25].mean(), ref[25:].mean()], 25)
    np.testing.assert_allclose(o[: w - 6], np.tile((ref - centre) / pitch, (w - 6, 1)))
    np.testing.assert_allclose(o[w - 6 :], (x[arm:9] - centre) / pitch)
    # frame 20: the last w frames
    o = outs[20][:w]
    first = x[20 - w + 1]
    centre = np.repeat([first[:25].mean(), first[25:].mean()], 25)
    np.testing.assert_allclose(o, (x[11:21] - centre) / pitch)
    # a reset starts a new stream: nothing decided before it is armed again
    pipe.reset()
    assert pipe(x[:1])[w, 0] == 0


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"arm": -1}, "arm"),
        ({"window": 1}, "window"),
        ({"min_frames": 11}, "min_frames"),
        ({"horizon": 0}, "horizon"),
        ({"fingertips": 0}, "fingertips"),
        ({"fingertips": 3}, "3 x 2K"),
        ({"extra": 1}, "extra"),
    ],
)
def test_contact_window_refuses_bad_parameters(change: dict, field: str) -> None:
    step = {"op": "contact_window", "arm": 3, "window": 10, "min_frames": 4, **change}
    with pytest.raises(BundleError, match=field):
        Pipeline([step], (1, 50), "manifest.json")


def test_contact_window_refuses_a_window_of_frames() -> None:
    step = {"op": "contact_window", "arm": 3, "window": 10, "min_frames": 4}
    with pytest.raises(BundleError, match="one frame"):
        Pipeline([step], (5, 50), "manifest.json")


@pytest.mark.parametrize(
    ("quantity", "horizon"), [("divergence_per_path", 60), ("contraction", None)]
)
def test_onnx_graph_with_the_step_decides_as_the_detector(
    quantity: str, horizon: int | None
) -> None:
    from slipkit.export.detector_parity import check_detector_parity
    from slipkit.export.registry import StreamContext, runtime_steps
    from slipkit.families.gelsight.export import export_pin_contact

    X, seg = _recordings()
    det = PinContactDetector(quantity=quantity, horizon=horizon, threshold=None)
    det.fit(X, np.zeros(len(X), int), segments=seg)
    s = det.decision_function(X, segments=seg)
    finite = s[np.isfinite(s)]
    det.set_params(threshold=float(np.median(finite)))
    det.fit(X, np.zeros(len(X), int), segments=seg)
    graph = export_pin_contact(det)
    assert graph.window == 1
    assert graph.first_decision == 7
    assert graph.preprocessing[0]["op"] == "contact_window"
    report = check_detector_parity(det, graph, X, segments=seg)
    assert report["passed"], report
    assert report["n_finite_mismatch"] == 0
    assert report["max_rel_diff"] < 1e-4
    ctx = StreamContext("camera_0", [], [], [], lambda ids: [])
    steps = runtime_steps(det, ctx)
    assert steps.steps == list(graph.preprocessing)


@pytest.mark.parametrize("opset", [17, 18])
def test_two_fingertip_graph_decides_as_the_detector(opset: int) -> None:
    from slipkit.export.detector_parity import check_detector_parity
    from slipkit.families.gelsight.export import export_pin_contact

    both, _, _, seg = _two_fingertips()
    det = PinContactDetector(horizon=60, fingertips=2, threshold=0.01)
    det.fit(both, np.zeros(len(both), int), segments=seg)
    s = det.decision_function(both, segments=seg)
    det.set_params(threshold=float(np.median(s[np.isfinite(s)])))
    det.fit(both, np.zeros(len(both), int), segments=seg)
    graph = export_pin_contact(det, opset=opset)
    assert graph.preprocessing[0]["fingertips"] == 2
    assert graph.input_shape == ("batch", 51, 100)
    report = check_detector_parity(det, graph, both, segments=seg)
    assert report["passed"], report
    assert report["n_finite_mismatch"] == 0


def test_bundle_in_the_runtime_loop_decides_as_the_detector(tmp_path: Path) -> None:
    """The bundle (graph + contact_window), each recording through StreamLoop from a
    reset, decides as the batch detector at every frame from its first decision."""
    from slipkit.families.gelsight.export import export_pin_contact
    from slipkit.runtime import StreamLoop, load_bundle, write_bundle

    X, seg = _recordings()
    det = PinContactDetector(horizon=60, threshold=None)
    det.fit(X, np.zeros(len(X), int), segments=seg)
    s = det.decision_function(X, segments=seg)
    det.set_params(threshold=float(np.median(s[np.isfinite(s)])))
    det.fit(X, np.zeros(len(X), int), segments=seg)
    graph = export_pin_contact(det)
    decision = {**graph.decision(), "positive": "1"}
    del decision["threshold"]
    manifest = {
        "name": "gelsight_contact",
        "frame": {
            "streams": ["camera_0"],
            "channels": [f"x_{i}" for i in range(25)] + [f"y_{i}" for i in range(25)],
            "shape": [50],
            "window": graph.window,
            "hop": graph.hop,
            "rate_hz": 25.0,
        },
        "preprocessing": [dict(st) for st in graph.preprocessing],
        "inputs": [
            {
                "name": graph.input_name,
                "dtype": graph.input_dtype,
                "shape": [1, *graph.input_shape[1:]],
            }
        ],
        "outputs": [{"name": "score", "dtype": "float32"}],
        "decision": decision,
        "threshold": graph.threshold,
        "debounce": {"k": 1},
        "budget_ms": {"frame_period": 40.0, "p99": 4.0},
        "opset": graph.opset,
        "producer": graph.producers,
    }
    loop = StreamLoop(
        load_bundle(write_bundle(tmp_path / "gs", graph.serialize(), manifest))
    )
    fired = 0
    for k in range(3):
        x = X[seg == k]
        loop.reset()
        for row in x:
            loop.step(row.astype(np.float32))
        res = loop.result()
        later = res.frame >= graph.first_decision
        ref = det.decision_function(x)[res.frame[later]]
        assert (ref >= det.threshold_).tolist() == res.slip[later].tolist()
        assert not res.slip[~later].any()
        fired += int(res.slip.sum())
    assert fired > 0
