"""FrameGRUDetector: a per-frame GRU with a recording-long state, batch and streaming forms."""

from __future__ import annotations

import numpy as np
import pytest

from slipkit.models.frame_gru import FrameGRUDetector


def recordings(n: int = 6, length: int = 120, seed: int = 0) -> tuple[np.ndarray, ...]:
    """``n`` two-channel recordings: noise, then from a random onset a vibration on channel 0."""
    rng = np.random.default_rng(seed)
    xs, ys, segs = [], [], []
    for i in range(n):
        x = rng.normal(0.0, 0.1, size=(length, 2)) + np.array([5.0, -2.0])
        onset = int(rng.integers(length // 3, 2 * length // 3))
        t = np.arange(length - onset)
        x[onset:, 0] += np.sin(2.1 * t) * 0.8
        y = np.zeros(length, dtype=int)
        y[onset:] = 1
        xs.append(x)
        ys.append(y)
        segs.append(np.full(length, i))
    return np.vstack(xs), np.concatenate(ys), np.concatenate(segs)


@pytest.fixture(scope="module")
def fitted() -> FrameGRUDetector:
    X, y, seg = recordings()
    return FrameGRUDetector(hidden=8, chunk=32, epochs=15).fit(X, y, segments=seg)


def test_batch_scores_equal_the_streaming_form(fitted: FrameGRUDetector) -> None:
    """Per recording, decision_function equals the stream's scores sample by sample."""
    X, _, seg = recordings(3, seed=1)
    batch = fitted.decision_function(X, segments=seg)
    stream = np.concatenate([fitted.replay(X[seg == i])[0] for i in range(3)])
    np.testing.assert_allclose(stream, batch, rtol=0, atol=1e-12)


def test_nonfinite_sample_scores_minus_inf_and_restarts_the_state(
    fitted: FrameGRUDetector,
) -> None:
    """A NaN sample scores -inf and the samples after it score as a fresh recording."""
    X, _, _ = recordings(1, seed=2)
    Xn = X.copy()
    Xn[40, 1] = np.nan
    s = fitted.decision_function(Xn)
    fresh = fitted.decision_function(X[41:])
    assert -np.inf == s[40]
    np.testing.assert_allclose(s[41:], fresh, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fitted.replay(Xn)[0], s, rtol=0, atol=1e-12)


def test_same_seed_same_weights() -> None:
    """Two fits with the same random_state give the same scores and threshold."""
    X, y, seg = recordings(3)
    a = FrameGRUDetector(hidden=4, epochs=3).fit(X, y, segments=seg)
    b = FrameGRUDetector(hidden=4, epochs=3).fit(X, y, segments=seg)
    assert a.threshold_ == b.threshold_
    np.testing.assert_array_equal(a.decision_function(X), b.decision_function(X))


def test_learns_the_vibration(fitted: FrameGRUDetector) -> None:
    """On held-out recordings the slip logit separates vibration from rest (AUC > 0.8)."""
    from sklearn.metrics import roc_auc_score

    X, y, seg = recordings(4, seed=3)
    s = fitted.decision_function(X, segments=seg)
    assert True is bool(roc_auc_score(y, s) > 0.8)
