"""Metric helpers: names and numbers as scikit-learn computes them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slipkit.evaluate.metrics import (
    classification_metrics,
    delay_summary,
    regression_metrics,
)


def test_classification_metrics_match_hand_counts() -> None:
    """Accuracy, recall per class and the confusion matrix follow the label order given."""
    y = ["static", "static", "slip", "slip"]
    p = ["static", "slip", "slip", "slip"]
    m = classification_metrics(y, p, ["static", "slip"])
    assert 0.75 == m["accuracy"]
    assert {"static": 0.5, "slip": 1.0} == m["recall"]
    assert [[1, 1], [0, 2]] == m["confusion"]
    assert 0.75 == m["balanced_accuracy"]


def test_classification_metrics_one_class_present() -> None:
    """With one true class the balanced accuracy is undefined (NaN), not an error."""
    m = classification_metrics(["a", "a"], ["a", "b"], ["a", "b"])
    assert math.isnan(m["balanced_accuracy"])
    assert math.isnan(m["recall"]["b"])


def test_regression_metrics_rmse_and_smse() -> None:
    """RMSE is the root mean square error; SMSE divides the MSE by the truth's variance."""
    truth = np.array([[0.0, 1.0], [2.0, 1.0], [4.0, 1.0]])
    pred = truth + np.array([[1.0, 0.0], [-1.0, 0.0], [1.0, 0.5]])
    m = regression_metrics(truth, pred, ["x", "y"])
    assert pytest.approx(1.0) == m["rmse"]["x"]
    assert pytest.approx(1.0 / (8.0 / 3.0)) == m["smse"]["x"]
    assert math.isnan(m["smse"]["y"])  # constant truth: no variance to compare with


def test_delay_summary_counts_missed_and_early() -> None:
    """NaN delays count as missed, negative ones as early; ms use the frame rate."""
    s = delay_summary([1.0, np.nan, -2.0, 3.0], rate_hz=100.0)
    assert (4, 3, 1, 1) == (s["n_trials"], s["detected"], s["missed"], s["early"])
    assert 10.0 == s["median_ms"]
    assert [1.0, None, -2.0, 3.0] == s["delay_frames"]
