"""The contract every analytic detector follows.

A detector reads one or more recordings of a sampled stream, in time order, as a
2-D array ``X`` of shape (n_samples, n_channels). ``segments`` (optional, one id per
sample) says where one recording ends and the next begins: all state (rest means,
filters, windows) restarts at every change of id. Without ``segments`` ``X`` is
one recording.

Two forms compute the same decisions:

* **batch** -- :meth:`StreamDetector.decision_function` / :meth:`predict` over whole
  recordings, vectorised with numpy / scipy;
* **streaming** -- :meth:`StreamDetector.stream` returns a :class:`DetectorStream`
  whose ``update(sample)`` takes one sample (n_channels,) and returns
  ``(score, decision)`` with O(1) state per step: the form the runtime loop runs.

Tests replay recordings through both and require equal decisions (and scores
equal to floating-point round-off).

``fit`` learns nothing but the decision threshold: with ``threshold=None`` it
computes the per-sample score on labelled recordings, takes scikit-learn's ROC curve
and keeps the point that maximises Youden's J = TPR - FPR (``roc_point="youden"``)
or the point nearest the ideal corner (``"closest"``); a number in ``threshold``
fixes it (the paper's value) and ``fit`` then only records the ROC for the report.
A detector the paper calibrates in another way (a regression) overrides ``_calibrate``.
"""

from __future__ import annotations

import itertools
from abc import abstractmethod
from numbers import Real
from typing import Any, ClassVar, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.metrics import roc_auc_score, roc_curve
from sklearn.utils._param_validation import StrOptions
from sklearn.utils.validation import check_is_fitted, validate_data

FloatArray = NDArray[np.float64]


class DetectorStream(Protocol):
    """Sample-by-sample form of a detector (O(1) state per step)."""

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        """Feed one sample (n_channels,); return (score, slip decision) at that sample."""
        ...

    def reset(self) -> None:
        """Forget all state (a new recording starts)."""
        ...


def segment_bounds(n: int, segments: ArrayLike | None) -> list[tuple[int, int]]:
    """(start, stop) of every run of equal ids in ``segments`` (whole range if None)."""
    if segments is None:
        return [(0, n)]
    seg = np.asarray(segments)
    if seg.shape != (n,):
        raise ValueError(f"segments must have shape ({n},) like X; got {seg.shape}")
    if n == 0:
        return []
    change = np.flatnonzero(seg[1:] != seg[:-1]) + 1
    edges = np.concatenate([[0], change, [n]])
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges)]


class StreamDetector(ClassifierMixin, BaseEstimator):
    """Base class of the analytic detectors: ROC-chosen threshold, batch + streaming.

    Subclasses implement :meth:`_scores` (batch score of ONE recording) and
    :meth:`_new_stream` (the streaming form), and declare their hyper-parameters
    (plus ``threshold`` and ``roc_point``) in ``__init__`` and
    ``_parameter_constraints``. A sample is slip when ``score >= threshold_``; a
    sample where the detector cannot decide yet (warm-up) scores ``-inf``.

    Attributes
    ----------
    threshold_ : float
        The decision threshold in the score's unit.
    classes_ : ndarray
        ``[0, 1]`` (1 = slip).
    roc_fpr_, roc_tpr_, roc_thresholds_ : ndarray
        The ROC curve on the calibration data (scikit-learn ``roc_curve``).
    auc_ : float
        Area under it (NaN if the labels hold one class only).
    tpr_, tnr_, fpr_, fnr_ : float
        Rates at ``threshold_`` on the calibration samples.
    n_features_in_ : int
        Channels seen in ``fit``.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "threshold": [Real, None],
        "roc_point": [StrOptions({"youden", "closest"})],
    }
    #: channels the detector needs (None: any number)
    n_channels: ClassVar[int | None] = 1

    def __init__(self, *, threshold: float | None = None, roc_point: str = "youden"):
        self.threshold = threshold
        self.roc_point = roc_point

    # -- subclass hooks --------------------------------------------------------
    @abstractmethod
    def _scores(self, X: FloatArray) -> FloatArray:
        """Per-sample score of one recording X (n_samples, n_channels)."""

    @abstractmethod
    def _new_stream(self) -> DetectorStream:
        """A fresh streaming state using the fitted ``threshold_``."""

    def _check_X(self, X: ArrayLike, *, reset: bool) -> FloatArray:
        # ensure_all_finite=False: NaN samples (dropped frames) are the detector's to handle.
        Xv = np.asarray(
            validate_data(
                self, X, reset=reset, dtype=np.float64, ensure_all_finite=False
            )
        )
        if self.n_channels is not None and Xv.shape[1] != self.n_channels:
            raise ValueError(
                f"{type(self).__name__} reads {self.n_channels} channel(s) per sample; "
                f"X has {Xv.shape[1]}"
            )
        return Xv

    # -- batch -----------------------------------------------------------------
    def _all_scores(self, X: FloatArray, segments: ArrayLike | None) -> FloatArray:
        out = np.empty(len(X), dtype=np.float64)
        for a, b in segment_bounds(len(X), segments):
            out[a:b] = self._scores(X[a:b])
        return out

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> StreamDetector:
        """Choose ``threshold_`` on labelled recordings (or record the ROC of a fixed one).

        Parameters
        ----------
        X : array_like (n_samples, n_channels)
            Recordings in time order.
        y : array_like (n_samples,)
            1 (or True) where the sample is slip, else 0.
        segments : array_like (n_samples,), optional
            Recording id of every sample.
        """
        self._validate_params()
        Xv = self._check_X(X, reset=True)
        yv = np.asarray(y).astype(int).reshape(-1)
        if yv.shape != (len(Xv),):
            raise ValueError(f"y must have shape ({len(Xv)},); got {yv.shape}")
        self.classes_ = np.array([0, 1])
        scores = self._all_scores(Xv, segments)
        self._calibrate(Xv, yv, scores, segments)
        return self

    def _calibrate(
        self,
        X: FloatArray,
        y: NDArray[np.int_],
        scores: FloatArray,
        segments: ArrayLike | None,
    ) -> None:
        finite = np.isfinite(scores)
        s = np.where(finite, scores, np.finfo(np.float64).min)
        two = len(np.unique(y)) == 2
        if two:
            fpr, tpr, thr = roc_curve(y, s)
            self.roc_fpr_, self.roc_tpr_, self.roc_thresholds_ = fpr, tpr, thr
            self.auc_ = float(roc_auc_score(y, s))
        else:
            empty = np.empty(0)
            self.roc_fpr_, self.roc_tpr_, self.roc_thresholds_ = empty, empty, empty
            self.auc_ = float("nan")
        if self.threshold is not None:
            self.threshold_ = float(self.threshold)
        elif not two:
            raise ValueError(
                "choosing a threshold on the ROC needs slip and non-slip samples; "
                f"y holds only {np.unique(y).tolist()} (or set threshold=...)"
            )
        else:
            usable = np.isfinite(thr) & (thr > np.finfo(np.float64).min)
            fpr_u, tpr_u, thr_u = fpr[usable], tpr[usable], thr[usable]
            if self.roc_point == "youden":
                k = int(np.argmax(tpr_u - fpr_u))
            else:
                k = int(np.argmin(np.hypot(fpr_u, 1.0 - tpr_u)))
            self.threshold_ = float(thr_u[k])
        pred = s >= self.threshold_
        pos, neg = y == 1, y == 0
        self.tpr_ = float(pred[pos].mean()) if pos.any() else float("nan")
        self.fnr_ = 1.0 - self.tpr_
        self.fpr_ = float(pred[neg].mean()) if neg.any() else float("nan")
        self.tnr_ = 1.0 - self.fpr_

    def decision_function(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FloatArray:
        """Per-sample score (slip when ``>= threshold_``; ``-inf`` during warm-up)."""
        check_is_fitted(self, "threshold_")
        # reset=False: keep n_features_in_ from fit, only check the shape.
        return self._all_scores(self._check_X(X, reset=False), segments)

    def predict(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> NDArray[np.int_]:
        """Per-sample decision, 1 = slip."""
        return (self.decision_function(X, segments=segments) >= self.threshold_).astype(
            int
        )

    # -- streaming -------------------------------------------------------------
    def stream(self) -> DetectorStream:
        """The sample-by-sample form, starting empty (fitted detectors only)."""
        check_is_fitted(self, "threshold_")
        return self._new_stream()

    def replay(self, X: ArrayLike) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Run one recording through :meth:`stream`, sample by sample (for tests/benchmarks)."""
        state = self.stream()
        Xv = np.asarray(X, dtype=np.float64)
        scores = np.empty(len(Xv))
        dec = np.empty(len(Xv), dtype=bool)
        for i, row in enumerate(Xv):
            scores[i], dec[i] = state.update(row)
        return scores, dec

    def roc_report(self) -> dict[str, Any]:
        """The calibration point and curve, JSON-able (for ``metrics.json``)."""
        check_is_fitted(self, "threshold_")
        return {
            "threshold": self.threshold_,
            "auc": self.auc_,
            "tpr": self.tpr_,
            "tnr": self.tnr_,
            "fpr": self.fpr_,
            "fnr": self.fnr_,
            "roc": {
                "fpr": self.roc_fpr_.tolist(),
                "tpr": self.roc_tpr_.tolist(),
                "thresholds": [
                    None if not np.isfinite(v) else float(v)
                    for v in self.roc_thresholds_
                ],
            },
        }
