"""Metrics shared by the tasks, as JSON-able dicts.

scikit-learn computes every score; these helpers only choose the set each family
reports and give them stable names in ``metrics.json``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from sklearn.metrics import (
    accuracy_score,
    balanced_accuracy_score,
    confusion_matrix,
    f1_score,
    mean_squared_error,
)


def classification_metrics(
    y_true: ArrayLike, y_pred: ArrayLike, labels: Sequence[Any]
) -> dict[str, Any]:
    """Accuracy, balanced accuracy, macro F1, per-class recall and the confusion matrix.

    ``labels`` fixes the row/column order of ``confusion`` (rows: true class).
    """
    yt = np.asarray(y_true)
    yp = np.asarray(y_pred)
    labels = list(labels)
    cm = confusion_matrix(yt, yp, labels=labels)
    support = cm.sum(axis=1)
    recall = np.divide(
        np.diag(cm), support, out=np.full(len(labels), np.nan), where=support > 0
    )
    present = [lab for lab, n in zip(labels, support, strict=True) if n > 0]
    return {
        "n": len(yt),
        "accuracy": float(accuracy_score(yt, yp)),
        "balanced_accuracy": float(balanced_accuracy_score(yt, yp))
        if len(present) > 1
        else float("nan"),
        "f1_macro": float(
            f1_score(yt, yp, labels=present, average="macro", zero_division=0)
        ),
        "recall": {str(lab): float(r) for lab, r in zip(labels, recall, strict=True)},
        "labels": [str(lab) for lab in labels],
        "confusion": cm.tolist(),
    }


def regression_metrics(
    y_true: ArrayLike, y_pred: ArrayLike, names: Sequence[str]
) -> dict[str, Any]:
    """Per-output RMSE and SMSE (MSE / variance of the truth), as in Su et al. 2015.

    SMSE is NaN for an output whose truth is constant.
    """
    yt = np.atleast_2d(np.asarray(y_true, dtype=np.float64))
    yp = np.atleast_2d(np.asarray(y_pred, dtype=np.float64))
    if yt.shape[0] == 1 and len(names) == 1:
        yt, yp = yt.T, yp.T
    mse = np.asarray(mean_squared_error(yt, yp, multioutput="raw_values"))
    var = yt.var(axis=0)
    # np.var of a constant can be round-off (0.1 x 1000 -> 1.9e-34), not 0: test the range.
    varies = (var > 0) & (np.ptp(yt, axis=0) > 0)
    smse = np.divide(mse, var, out=np.full_like(mse, np.nan), where=varies)
    return {
        "n": int(yt.shape[0]),
        "rmse": {n: float(v) for n, v in zip(names, np.sqrt(mse), strict=True)},
        "smse": {n: float(v) for n, v in zip(names, smse, strict=True)},
    }


def delay_summary(delays_frames: ArrayLike, rate_hz: float) -> dict[str, Any]:
    """Detection delays (frames after onset; NaN = missed) as counts and ms statistics."""
    d = np.asarray(delays_frames, dtype=np.float64)
    hit = d[np.isfinite(d)]
    ms = hit * 1000.0 / rate_hz

    def stat(fn: Any, x: np.ndarray) -> float:
        return float(fn(x)) if len(x) else float("nan")

    return {
        "n_trials": len(d),
        "detected": len(hit),
        "missed": int(len(d) - len(hit)),
        "early": int((hit < 0).sum()),
        "delay_frames": [None if not np.isfinite(v) else float(v) for v in d],
        "median_frames": stat(np.median, hit),
        "median_ms": stat(np.median, ms),
        "mean_ms": stat(np.mean, ms),
        "max_ms": stat(np.max, ms),
    }
