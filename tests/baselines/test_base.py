"""The StreamDetector contract itself, through two trivial subclasses."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.typing import ArrayLike
from sklearn.exceptions import NotFittedError

from slipkit.baselines.base import FloatArray, StreamDetector, segment_bounds


class Identity(StreamDetector):
    """Score = the sample itself (stateless)."""

    def _scores(self, X: FloatArray) -> FloatArray:
        return X[:, 0].copy()

    def _new_stream(self) -> _IdentityStream:
        return _IdentityStream(self.threshold_)


class _IdentityStream:
    def __init__(self, threshold: float) -> None:
        self.threshold = threshold

    def reset(self) -> None:
        """Nothing to forget."""

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        x = float(np.asarray(sample).reshape(-1)[0])
        return x, x >= self.threshold


class Running(StreamDetector):
    """Score = running sum within the recording (stateful: restarts per segment)."""

    def _scores(self, X: FloatArray) -> FloatArray:
        return np.cumsum(X[:, 0])

    def _new_stream(self) -> _IdentityStream:  # not used by these tests
        return _IdentityStream(self.threshold_)


def step(n: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """A step from 0 to 1 at the middle, with the labels it implies."""
    y = (np.arange(n) >= n // 2).astype(int)
    return y[:, None].astype(float), y


def test_roc_choice_separates_a_step() -> None:
    """With threshold=None, fit picks a threshold that splits a clean step perfectly."""
    X, y = step()
    det = Identity().fit(X, y)
    assert 1.0 == det.auc_
    assert (1.0, 1.0) == (det.tpr_, det.tnr_)
    assert 0.0 < det.threshold_ <= 1.0
    assert y.tolist() == det.predict(X).tolist()


@pytest.mark.parametrize("point", ["youden", "closest"])
def test_both_roc_points_choose_a_separating_threshold(point: str) -> None:
    """Youden's J and the closest-to-corner point agree on a noisy separable step."""
    rng = np.random.default_rng(0)
    X, y = step(200)
    X = X + rng.normal(0, 0.1, X.shape)
    det = Identity(roc_point=point).fit(X, y)
    assert det.tpr_ > 0.95
    assert det.tnr_ > 0.95


def test_fixed_threshold_is_kept_and_the_roc_recorded() -> None:
    """A number in threshold is used as is; fit still records the ROC and the rates."""
    X, y = step()
    det = Identity(threshold=0.25).fit(X, y)
    assert 0.25 == det.threshold_
    assert 1.0 == det.auc_
    assert len(det.roc_fpr_) == len(det.roc_tpr_) > 1
    assert 0.0 == det.fpr_


def test_one_class_labels_need_a_fixed_threshold() -> None:
    """Only non-slip samples: ROC choice is refused; a fixed threshold works (AUC NaN)."""
    X = np.zeros((20, 1))
    y = np.zeros(20, int)
    with pytest.raises(ValueError, match="slip and non-slip"):
        Identity().fit(X, y)
    det = Identity(threshold=1.0).fit(X, y)
    assert np.isnan(det.auc_)
    assert 0 == len(det.roc_fpr_)


def test_segments_restart_the_state() -> None:
    """With segments, each recording is scored from a fresh state."""
    X = np.ones((10, 1))
    seg = np.array([0] * 4 + [1] * 6)
    det = Running(threshold=0.0).fit(X, np.zeros(10, int))
    expected = [1, 2, 3, 4, 1, 2, 3, 4, 5, 6]
    assert expected == det.decision_function(X, segments=seg).tolist()
    assert list(range(1, 11)) == det.decision_function(X).tolist()


def test_segment_bounds_and_its_shape_check() -> None:
    """segment_bounds splits runs of equal ids and refuses a mismatched length."""
    assert [(0, 2), (2, 3), (3, 5)] == segment_bounds(5, [7, 7, 1, 7, 7])
    assert [(0, 5)] == segment_bounds(5, None)
    with pytest.raises(ValueError, match="segments must have shape"):
        segment_bounds(5, [0, 1])


def test_channel_count_and_fit_state_are_checked() -> None:
    """Two channels for a one-channel detector and predicting before fit are refused."""
    with pytest.raises(ValueError, match="1 channel"):
        Identity(threshold=0.0).fit(np.zeros((5, 2)), np.zeros(5))
    with pytest.raises(NotFittedError):
        Identity().predict(np.zeros((5, 1)))


def test_replay_matches_batch_and_report_is_json() -> None:
    """replay (streaming) gives the batch scores; roc_report serialises to JSON."""
    X, y = step(40)
    det = Identity().fit(X, y)
    scores, dec = det.replay(X)
    assert det.decision_function(X).tolist() == scores.tolist()
    assert det.predict(X).astype(bool).tolist() == dec.tolist()
    report = json.loads(json.dumps(det.roc_report()))
    assert det.threshold_ == report["threshold"]
