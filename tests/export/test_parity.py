"""check_parity: the issue's rule (99.9 % agreement, disagreements near the threshold, 1e-4 for networks)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.datasets import make_classification, make_regression
from sklearn.linear_model import LinearRegression
from torch import nn

from slipkit.export import ExportError, check_parity, export
from slipkit.export.parity import _decisions
from slipkit.models import TacTipSVM


class Shifted:
    """An estimator whose score is another one's plus a fixed offset (a broken export stand-in)."""

    def __init__(self, inner, offset: float, method: str = "decision_function") -> None:
        self.inner, self.offset, self.method = inner, offset, method

    def decision_function(self, X):
        return self.inner.decision_function(X) + self.offset

    def predict(self, X):
        return self.inner.predict(X) + self.offset

    def __call__(self, x):
        return self.inner(x) + self.offset


@pytest.fixture(scope="module")
def svm_and_graph():
    """A binary RBF TacTipSVM on 2000 frames and its graph."""
    X, y = make_classification(n_samples=2000, n_features=6, flip_y=0.2, random_state=0)
    svm = TacTipSVM(C=1.0, gamma="scale").fit(X, y)
    return svm, export(svm), X


def test_faithful_export_passes_with_the_stated_epsilon(svm_and_graph):
    """The SVM's own graph: every decision agrees, eps = 1e-4 x max |score| is stated."""
    svm, graph, X = svm_and_graph
    report = check_parity(svm, graph, X)
    assert (True, 1.0, 2000) == (
        report["passed"],
        report["agreement"],
        report["n_frames"],
    )
    scale = np.max(np.abs(svm.decision_function(X)))
    assert pytest.approx(max(1e-4 * scale, 1e-4)) == report["score_eps"]
    assert report["max_rel_diff"] <= 1e-4


def test_flips_far_from_the_threshold_fail(svm_and_graph):
    """A reference shifted by 0.5 flips frames up to 0.5 from the threshold: not within eps, failed."""
    svm, graph, X = svm_and_graph
    report = check_parity(Shifted(svm, 0.5), graph, X, score_eps=0.01)
    assert report["n_disagree"] > 0
    assert (False, False) == (report["passed"], report["disagreements_near_threshold"])


def test_flips_near_the_threshold_pass_only_while_rare(svm_and_graph):
    """One flip within eps (0.05 % of frames) passes; flipping > 0.1 % fails even within eps."""
    svm, graph, X = svm_and_graph
    score = svm.decision_function(X)
    closest = score[np.argmin(np.abs(score))]
    # Moves only the closest frame across 0, leaving it 0.01 |s| from the threshold.
    rare = check_parity(Shifted(svm, -1.01 * closest), graph, X, score_eps=0.01)
    assert (1, True, True) == (
        rare["n_disagree"],
        rare["disagreements_near_threshold"],
        rare["passed"],
    )
    many = check_parity(Shifted(svm, 0.5), graph, X, score_eps=10.0)
    assert (True, False) == (many["disagreements_near_threshold"], many["passed"])
    assert many["agreement"] < 0.999


def test_networks_and_regressors_need_max_difference_within_atol():
    """Agreeing decisions are not enough for networks; regressors fail on a 1e-3 offset at atol 1e-4."""
    net = nn.Sequential(nn.Linear(3, 2), nn.Softmax(dim=-1))
    graph = dataclasses.replace(export(net, input_shape=(3,)), classes=("a", "b"))
    X = np.random.default_rng(0).normal(size=(50, 3)).astype(np.float32)
    assert check_parity(net, graph, X)["passed"]
    report = check_parity(Shifted(net, 2e-4), graph, X)
    assert (1.0, False) == (report["agreement"], report["passed"])
    Xr, yr = make_regression(n_samples=40, n_features=3, random_state=0)
    reg = LinearRegression().fit(Xr, yr)
    report = check_parity(Shifted(reg, 1e-3), export(reg), Xr)
    assert (False, 0.0) == (report["passed"], report["agreement"])
    with pytest.raises(ExportError, match="at least one held-out frame"):
        check_parity(reg, export(reg), Xr[:0])


@settings(max_examples=100, deadline=None)
@given(p=st.floats(0.0, 1.0), k=st.integers(2, 5))
def test_probability_margin_is_half_the_gap_between_the_best_two(p: float, k: int):
    """For per-class scores the distance to the boundary is (best - second) / 2; |p - 0.5| for two classes."""
    rest = np.full(k - 1, (1.0 - p) / (k - 1))
    scores = np.r_[p, rest][None, :]
    decision, margin = _decisions(scores, None)
    top = np.sort(scores[0])
    assert pytest.approx((top[-1] - top[-2]) / 2.0) == float(margin[0])
    assert int(np.argmax(scores[0])) == int(decision[0])
    if k == 2:
        assert pytest.approx(abs(p - 0.5)) == float(margin[0])
