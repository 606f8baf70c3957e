"""Pin-field features, the divergence detector, its streaming form and its ONNX graph."""

from __future__ import annotations

import numpy as np
import pytest

from slipkit.families.gelsight.detectors import choose_threshold, first_alarm
from slipkit.families.gelsight.features import (
    FEATURES,
    FeatureStream,
    affine_fit,
    trial_features,
    window_features,
)
from slipkit.families.gelsight.stream import PinDivergenceDetector, window_divergence


def _grid(n: int = 6) -> np.ndarray:
    xs, ys = np.meshgrid(np.arange(n) * 30.0, np.arange(n) * 30.0)
    return np.column_stack([xs.ravel(), ys.ravel()])


def _rows(points: np.ndarray) -> np.ndarray:
    """(n, K, 2) -> (n, 2K) rows x block, y block."""
    return np.concatenate([points[..., 0], points[..., 1]], axis=-1)


def test_affine_fit_recovers_a_known_deformation() -> None:
    p = _grid()
    a = np.array([[0.02, -0.01], [0.03, 0.05]])
    d = (p - p.mean(axis=0)) @ a.T + [1.5, -2.0]
    got_a, got_b, resid = affine_fit(p, d)
    assert np.allclose(got_a, a)
    assert np.allclose(got_b, [1.5, -2.0])
    assert resid < 1e-9
    f = dict(zip(FEATURES, window_features(np.stack([p, p + d]) / 30.0), strict=True))
    assert f["divergence"] == pytest.approx(0.07)
    assert f["curl"] == pytest.approx(0.04)
    assert window_divergence(_rows(p), _rows(p + d)) == pytest.approx(0.07)


def test_steady_drift_is_straight_and_a_shake_is_not() -> None:
    p = _grid()
    drift = np.stack([p + np.array([0.5 * t, 0.0]) for t in range(20)])
    shake = np.stack([p + np.array([3.0 * np.sin(t), 0.0]) for t in range(20)])
    s = FEATURES.index("straightness")
    assert window_features(drift / 30)[s] == pytest.approx(1.0)
    assert window_features(shake / 30)[s] < 0.2


def test_feature_stream_matches_the_batch_features() -> None:
    rng = np.random.default_rng(0)
    p = _grid()
    frames = _rows(
        np.stack([p + rng.normal(0, 0.5, p.shape) + [0.3 * t, 0] for t in range(40)])
    )
    batch = trial_features(frames, window=10, arm=5)
    stream = FeatureStream(window=10, arm=5)
    rows = [stream.update(f) for f in frames]
    for t, r in enumerate(rows):
        if r is None:
            assert np.isnan(batch[t]).all()
        else:
            assert np.allclose(r, batch[t])


def test_choose_threshold_separates_and_first_alarm_finds_the_frame() -> None:
    thr = choose_threshold([0.1, 0.2, 0.9, 1.0], [0, 0, 1, 1])
    assert 0.2 < thr < 0.9
    assert first_alarm(np.array([np.nan, 0.1, 0.95, 2.0]), thr) == 2
    assert first_alarm(np.array([0.1, 0.1]), thr) is None


def _swelling(n: int = 60, rate: float = 0.002) -> np.ndarray:
    p = _grid()
    c = p.mean(axis=0)
    return _rows(np.stack([c + (p - c) * (1 + rate * t) for t in range(n)]))


def test_divergence_detector_streams_as_it_scores() -> None:
    x = _swelling()
    det = PinDivergenceDetector(window=10, threshold=0.015).fit(x, np.zeros(len(x)))
    scores, fired = det.replay(x)
    assert np.allclose(scores, det.decision_function(x))
    assert scores[9] == pytest.approx(9 * 0.002 * 2, rel=1e-6)
    assert fired[9:].all()
    assert not fired[:9].any()


def test_without_slip_labels_the_threshold_starts_at_a_quantile() -> None:
    x = _swelling()
    det = PinDivergenceDetector(window=10, quantile=0.5).fit(x, np.zeros(len(x)))
    finite = det.decision_function(x)
    assert det.threshold_ == pytest.approx(
        np.quantile(finite[np.isfinite(finite)], 0.5)
    )


def test_onnx_graph_scores_as_the_detector() -> None:
    ort = pytest.importorskip("onnxruntime")
    from slipkit.families.gelsight.export import export_pin_divergence

    rng = np.random.default_rng(1)
    x = _swelling() + rng.normal(0, 0.3, (60, 72))
    x[:, [3, 3 + 36]] = np.nan  # one pin missing throughout
    det = PinDivergenceDetector(window=10, threshold=0.01).fit(x, np.zeros(len(x)))
    graph = export_pin_divergence(det)
    sess = ort.InferenceSession(graph.model.SerializeToString())
    wins = np.stack([x[t - 9 : t + 1] for t in range(9, 60)]).astype(np.float32)
    got = sess.run(None, {graph.input_name: wins})[0]
    want = det.decision_function(x.astype(np.float32).astype(np.float64))[9:]
    assert np.allclose(got, want, rtol=1e-5, atol=1e-6)


def test_divergence_detector_refuses_odd_channels_and_too_short_recordings() -> None:
    with pytest.raises(ValueError, match="even number of channels"):
        PinDivergenceDetector(window=3).fit(np.zeros((10, 7)), np.zeros(10))
    with pytest.raises(ValueError, match="window of 25 frames"):
        PinDivergenceDetector(window=25).fit(_swelling(n=10), np.zeros(10))
