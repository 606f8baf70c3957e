"""Generic detectors for any sensor: analytic channel change and a learned window classifier."""

from __future__ import annotations

import numpy as np
import pytest

from slipkit.baselines.generic import ChannelChangeDetector
from slipkit.export import export
from slipkit.export.detectors import DetectorGraph, check_detector_parity
from slipkit.models.window_detector import WindowClassifierDetector


def recording(seed: int, *, n: int = 200, onset: int = 120, sign: float = -1.0):
    """Three channels in different units: ch0 ramps (sign) after the onset, ch1 (x100) gets
    noisier, ch2 is noise; labels 1 from the onset."""
    r = np.random.default_rng(seed)
    x = r.normal(0, 0.05, (n, 3))
    x[:, 1] *= 100
    x[onset:, 0] += sign * 0.2 * np.arange(1, n - onset + 1)
    x[onset:, 1] += r.normal(0, 20, n - onset)
    return x, (np.arange(n) >= onset).astype(int)


def stacked(seeds, **kw):
    """Recordings of ``seeds`` stacked, with their labels and segment ids."""
    parts = [recording(s, **kw) for s in seeds]
    X = np.vstack([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    return X, y, np.repeat(np.arange(len(parts)), len(parts[0][0]))


DETECTORS = [
    ChannelChangeDetector(),
    ChannelChangeDetector(feature="energy", window=8, combine="sum"),
    ChannelChangeDetector(polarity="learned", span=3),
    WindowClassifierDetector(window=8),
    WindowClassifierDetector(window=8, model="mlp", hidden=(16,)),
]


@pytest.mark.parametrize("det", DETECTORS, ids=repr)
def test_batch_equals_streaming_and_the_graph_decides_alike(det) -> None:
    """Batch and sample-by-sample scores agree; the ONNX window graph passes parity, a NaN sample included."""
    X, y, seg = stacked(range(4))
    det.fit(X, y, segments=seg)
    Xt, _, seg_t = stacked(range(10, 13))
    Xt[50, 1] = np.nan
    batch = det.decision_function(Xt[:200])
    stream, _ = det.replay(Xt[:200])
    np.testing.assert_allclose(stream, batch, rtol=1e-12, atol=1e-12)
    graph = export(det)
    assert isinstance(graph, DetectorGraph)
    report = check_detector_parity(det, graph, Xt, segments=seg_t)
    assert (True, 0, 0) == (
        report["passed"],
        report["n_disagree"],
        report["n_finite_mismatch"],
    )


@pytest.mark.parametrize("sign", [-1.0, 1.0])
def test_learned_polarity_follows_the_wiring(sign: float) -> None:
    """With polarity=learned the slip channel's sign is learned from the labels, either wiring."""
    X, y, seg = stacked(range(4), sign=sign)
    det = ChannelChangeDetector(polarity="learned").fit(X, y, segments=seg)
    assert sign == det.sign_[0]


def test_absolute_derivative_is_polarity_agnostic() -> None:
    """The absolute derivative detects the slips of either wiring with one threshold."""
    X, y, seg = stacked(range(4), sign=-1.0)
    det = ChannelChangeDetector().fit(X, y, segments=seg)
    Xr, yr, seg_r = stacked(range(20, 24), sign=1.0)
    pred = det.predict(Xr, segments=seg_r)
    fired = [bool(pred[seg_r == k][yr[seg_r == k] == 1].any()) for k in range(4)]
    assert [True] * 4 == fired


def test_scales_put_channels_in_different_units_on_one_footing() -> None:
    """Each channel's scale is its non-slip spread, so the x100 channel gets a ~100x scale."""
    X, y, seg = stacked(range(4))
    det = ChannelChangeDetector().fit(X, y, segments=seg)
    assert 50 < det.scale_[1] / det.scale_[2] < 200


def test_window_classifier_needs_both_classes() -> None:
    """Training windows of one class are refused with a message naming the classes."""
    X, _, seg = stacked(range(2))
    with pytest.raises(ValueError, match=r"hold only classes \[0\]"):
        WindowClassifierDetector().fit(X, np.zeros(len(X)), segments=seg)
