"""Generic slip detectors for a sensor slipkit has no model of (issue 14, "your own sensor").

Both read any stream of any number of channels, as every
:class:`~slipkit.baselines.base.StreamDetector` (batch and streaming forms agree, state
restarts per recording), so a new sensor gets an analytic and a learned detector from
configs alone (``docs/own-sensor.md``):

* :class:`ChannelChangeDetector` -- analytic: per channel the change over ``span``
  samples (``derivative``; absolute value, or the sign learned in ``fit``) or its RMS
  over the last ``window`` samples (``energy``, the energy of a high-passed signal:
  a first difference is a high-pass filter), each divided by its spread on the
  non-slip training samples so channels in different units add up, then combined
  over channels by ``max`` or ``sum``. ``fit`` learns only the per-channel scales and
  signs and the threshold (ROC).
* :class:`WindowClassifierDetector` -- learned: the last ``window`` samples of every
  channel -> per-channel window statistics
  (:class:`~slipkit.models.window_features.WindowStatistics`) -> standardise ->
  logistic regression or a small MLP (a scikit-learn Pipeline); the score is the slip
  probability at the window's last sample, the threshold again from the ROC. Windows
  never cross a recording boundary; a window holding a non-finite sample scores
  ``-inf`` (and is left out of training).
"""

from __future__ import annotations

from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from sklearn.base import clone
from sklearn.linear_model import LogisticRegression
from sklearn.neural_network import MLPClassifier
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils._param_validation import Interval, StrOptions

from slipkit.baselines.base import FloatArray, StreamDetector, segment_bounds
from slipkit.models.window_features import STATS, WindowStatistics

#: Smallest per-channel scale: a channel that never moves on non-slip samples gets
#: this instead of 0 (its changes then dominate, as they should).
MIN_SCALE = 1e-12


class _RingStream:
    """Streaming form of a detector whose score at a sample reads only the last
    ``detector.window_samples`` samples: a ring of them, scored by the batch code."""

    def __init__(self, detector: Any) -> None:
        self._detector = detector
        self._w = int(detector.window_samples)
        self._threshold = float(detector.threshold_)
        self.reset()

    def reset(self) -> None:
        """Forget the recording."""
        self._ring: list[FloatArray] = []

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        """Feed one sample (n_channels,); return (score, slip)."""
        self._ring.append(np.asarray(sample, dtype=np.float64).reshape(-1))
        if len(self._ring) > self._w:
            self._ring.pop(0)
        if len(self._ring) < self._w:
            return -np.inf, False
        score = float(self._detector._scores(np.stack(self._ring))[-1])
        return score, score >= self._threshold


class ChannelChangeDetector(StreamDetector):
    """Per-channel derivative or high-pass energy, scaled, combined over channels.

    Parameters
    ----------
    feature : {"derivative", "energy"}
        ``derivative``: ``(x[t] - x[t - span]) * rate_hz / span`` per channel (units
        per s); ``energy``: the RMS of that derivative over the last ``window``
        samples.
    span : int
        Samples of the backward difference.
    window : int
        Samples of the RMS (``energy`` only).
    rate_hz : float
        Sample rate (Hz), only to express the derivative per second (it cancels in the
        scaled score).
    polarity : {"abs", "learned"}
        ``derivative`` only: the absolute change (either direction is slip), or the
        change times a per-channel sign learned in ``fit`` (the sign of the mean
        derivative on slip samples minus that on non-slip samples).
    combine : {"max", "sum"}
        How the scaled channel scores make one score.
    threshold : float or None
        Slip when the score ``>= threshold`` (in non-slip spreads); None: ROC choice.
    roc_point : {"youden", "closest"}
        ROC point chosen when ``threshold`` is None.

    Attributes
    ----------
    sign_ : ndarray (n_channels,)
        +1 / -1 per channel (all +1 with ``polarity="abs"`` or ``energy``).
    scale_ : ndarray (n_channels,)
        Standard deviation of each channel's feature on the non-slip training samples.
    threshold_, classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "feature": [StrOptions({"derivative", "energy"})],
        "span": [Interval(Integral, 1, None, closed="left")],
        "window": [Interval(Integral, 1, None, closed="left")],
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "polarity": [StrOptions({"abs", "learned"})],
        "combine": [StrOptions({"max", "sum"})],
    }
    n_channels: ClassVar[int | None] = None

    def __init__(
        self,
        *,
        feature: str = "derivative",
        span: int = 1,
        window: int = 10,
        rate_hz: float = 1.0,
        polarity: str = "abs",
        combine: str = "max",
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.feature = feature
        self.span = span
        self.window = window
        self.rate_hz = rate_hz
        self.polarity = polarity
        self.combine = combine

    @property
    def window_samples(self) -> int:
        """Samples one score reads (the current one included)."""
        extra = int(self.window) - 1 if self.feature == "energy" else 0
        return int(self.span) + 1 + extra

    def _derivative(self, X: FloatArray) -> FloatArray:
        s = int(self.span)
        d = np.full(X.shape, np.nan)
        if len(X) > s:
            d[s:] = (X[s:] - X[:-s]) * (float(self.rate_hz) / s)
        return d

    def channel_features(self, X: FloatArray) -> FloatArray:
        """Unscaled per-channel feature of one recording (NaN in warm-up / missing)."""
        d = self._derivative(X)
        if self.feature == "derivative":
            sign = getattr(self, "sign_", None)
            return np.abs(d) if self.polarity == "abs" or sign is None else d * sign
        w = int(self.window)
        out = np.full(X.shape, np.nan)
        if len(X) >= w:
            out[w - 1 :] = np.sqrt(
                np.mean(sliding_window_view(d * d, w, axis=0), axis=-1)
            )
        return out

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> ChannelChangeDetector:
        """Learn the signs and scales per channel, then the threshold (ROC)."""
        self._validate_params()
        Xv = self._check_X(X, reset=True)
        yv = np.asarray(y).astype(int).reshape(-1)
        if yv.shape != (len(Xv),):
            raise ValueError(f"y must have shape ({len(Xv)},); got {yv.shape}")
        c = Xv.shape[1]
        self.sign_ = np.ones(c)
        if self.feature == "derivative" and self.polarity == "learned":
            d = np.vstack(
                [
                    self._derivative(Xv[a:b])
                    for a, b in segment_bounds(len(Xv), segments)
                ]
            )
            with np.errstate(invalid="ignore"):
                gap = np.nanmean(d[yv == 1], axis=0) - np.nanmean(d[yv == 0], axis=0)
            self.sign_ = np.where(np.nan_to_num(gap) < 0, -1.0, 1.0)
        f = np.vstack(
            [
                self.channel_features(Xv[a:b])
                for a, b in segment_bounds(len(Xv), segments)
            ]
        )
        rest = f[yv == 0]
        with np.errstate(invalid="ignore"):
            sd = np.array(
                [np.nanstd(col) if np.isfinite(col).any() else 0.0 for col in rest.T]
            )
        self.scale_ = np.maximum(np.nan_to_num(sd), MIN_SCALE)
        super().fit(Xv, yv, segments=segments)
        return self

    def _scores(self, X: FloatArray) -> FloatArray:
        z = self.channel_features(X) / self.scale_
        with np.errstate(invalid="ignore"):
            s = z.max(axis=1) if self.combine == "max" else z.sum(axis=1)
        return np.where(np.isfinite(s), s, -np.inf)

    def _new_stream(self) -> _RingStream:
        return _RingStream(self)


class WindowClassifierDetector(StreamDetector):
    """A learned per-sample slip classifier on windows of any stream (see the module doc).

    Parameters
    ----------
    window : int
        Samples per window (the current one last).
    stats : sequence of str
        Window statistics per channel (a subset of
        :data:`slipkit.models.window_features.STATS`).
    subtract_first : bool
        Subtract each window's first sample before the statistics.
    model : {"logreg", "mlp"}
        Logistic regression (``C``) or an MLP (``hidden``, ReLU, adam, early stopping).
    C : float
        Inverse L2 strength of the logistic regression.
    hidden : sequence of int
        MLP hidden layer sizes.
    class_weight : "balanced" or None
        Logistic regression class weights (slip samples are usually rare).
    random_state : int
        Seed of the MLP.
    threshold : float or None
        Slip when the slip probability ``>= threshold``; None: ROC choice.
    roc_point : {"youden", "closest"}
        ROC point chosen when ``threshold`` is None.

    Attributes
    ----------
    pipeline_ : sklearn.pipeline.Pipeline
        ``WindowStatistics -> StandardScaler -> classifier`` on flattened windows
        (time-major, ``window x n_channels``); exported whole by skl2onnx.
    threshold_, classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "window": [Interval(Integral, 1, None, closed="left")],
        "stats": [list, tuple],
        "subtract_first": ["boolean"],
        "model": [StrOptions({"logreg", "mlp"})],
        "C": [Interval(Real, 0, None, closed="neither")],
        "hidden": [list, tuple],
        "class_weight": [StrOptions({"balanced"}), None],
        "random_state": [Interval(Integral, 0, None, closed="left")],
    }
    n_channels: ClassVar[int | None] = None

    def __init__(
        self,
        *,
        window: int = 10,
        stats: Sequence[str] = STATS,
        subtract_first: bool = False,
        model: str = "logreg",
        C: float = 1.0,
        hidden: Sequence[int] = (32,),
        class_weight: str | None = "balanced",
        random_state: int = 0,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.window = window
        self.stats = stats
        self.subtract_first = subtract_first
        self.model = model
        self.C = C
        self.hidden = hidden
        self.class_weight = class_weight
        self.random_state = random_state

    @property
    def window_samples(self) -> int:
        """Samples one score reads."""
        return int(self.window)

    def _pipeline(self, n_channels: int) -> Pipeline:
        clf: Any
        if self.model == "logreg":
            clf = LogisticRegression(
                C=float(self.C), class_weight=self.class_weight, max_iter=2000
            )
        else:
            clf = MLPClassifier(
                hidden_layer_sizes=tuple(int(h) for h in self.hidden),
                early_stopping=True,
                max_iter=500,
                random_state=int(self.random_state),
            )
        return Pipeline(
            [
                (
                    "stats",
                    WindowStatistics(
                        n_channels=n_channels,
                        stats=tuple(self.stats),
                        subtract_first=bool(self.subtract_first),
                    ),
                ),
                ("scale", StandardScaler()),
                ("clf", clone(clf)),
            ]
        )

    def windows(self, X: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
        """Flattened windows of ONE recording and the sample each ends on."""
        w, c = int(self.window), X.shape[1]
        if len(X) < w:
            return np.empty((0, w * c)), np.empty(0, dtype=np.intp)
        view = sliding_window_view(X, (w, c))[:, 0]  # (n - w + 1, w, c)
        return view.reshape(len(view), w * c), np.arange(w - 1, len(X))

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> WindowClassifierDetector:
        """Fit the pipeline on the finite windows (label at the window's end), then the threshold."""
        self._validate_params()
        Xv = self._check_X(X, reset=True)
        yv = np.asarray(y).astype(int).reshape(-1)
        if yv.shape != (len(Xv),):
            raise ValueError(f"y must have shape ({len(Xv)},); got {yv.shape}")
        parts, labels = [], []
        for a, b in segment_bounds(len(Xv), segments):
            win, ends = self.windows(Xv[a:b])
            ok = np.isfinite(win).all(axis=1)
            parts.append(win[ok])
            labels.append(yv[a:b][ends[ok]])
        W = np.vstack(parts) if parts else np.empty((0, 0))
        wy = np.concatenate(labels) if labels else np.empty(0, int)
        if len(np.unique(wy)) < 2:
            raise ValueError(
                f"training windows of {self.window} samples hold only classes "
                f"{np.unique(wy).tolist()}; need slip and non-slip windows"
            )
        self.pipeline_ = self._pipeline(Xv.shape[1]).fit(W, wy)
        super().fit(Xv, yv, segments=segments)
        return self

    def _scores(self, X: FloatArray) -> FloatArray:
        out = np.full(len(X), -np.inf)
        win, ends = self.windows(X)
        if len(ends) == 0:
            return out
        ok = np.isfinite(win).all(axis=1)
        if ok.any():
            out[ends[ok]] = self.pipeline_.predict_proba(win[ok])[:, 1]
        return out

    def _new_stream(self) -> _RingStream:
        return _RingStream(self)


__all__ = ["MIN_SCALE", "ChannelChangeDetector", "WindowClassifierDetector"]
