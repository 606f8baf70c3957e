"""Generic slip detectors for a sensor slipkit has no model of ("your own sensor").

The analytic one reads any stream of any number of channels, as every
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
* :class:`slipkit.models.window_detector.WindowClassifierDetector` -- its learned
  counterpart (window statistics -> logistic regression or a small MLP), under the
  same contract so the same task scores both.
"""

from __future__ import annotations

from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from sklearn.utils._param_validation import Interval, StrOptions

from slipkit.baselines.base import FloatArray, StreamDetector, segment_bounds

#: Smallest per-channel scale: a channel that never moves on non-slip samples gets
#: this instead of 0 (its changes then dominate, as they should).
MIN_SCALE = 1e-12


class RingStream:
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


class OnsetCalibration:
    """``calibration="onset"``: a free threshold from a per-recording ROC, mid-gap.

    Mixed in before :class:`~slipkit.baselines.base.StreamDetector` by detectors with
    ``calibration`` ({"onset", "sample"}) and ``onset_frames`` (int or None)
    parameters. Units, one pair per training recording: its largest score in its
    first ``onset_frames`` slip-labelled samples (all of them for None) -- positive,
    "slip detected on time" -- and its largest score before its first slip sample --
    negative, "an alarm before the onset". The threshold is the best Youden point of
    that ROC, placed in the middle of the gap between unit scores that gives it
    rather than at its edge (scikit-learn's ROC thresholds are the unit scores
    themselves, so the edge is the weakest training slip: a test slip a little
    weaker would be missed). ``"sample"`` keeps the base class's per-sample ROC. The
    per-sample ROC is recorded either way.
    """

    calibration: str
    onset_frames: int | None
    threshold: float | None
    threshold_: float
    tpr_: float
    fnr_: float
    fpr_: float
    tnr_: float

    def onset_units(
        self, y: NDArray[np.int_], scores: FloatArray, segments: ArrayLike | None
    ) -> tuple[NDArray[np.int_], FloatArray]:
        """Per-recording units of the ``"onset"`` calibration: (label, largest score)."""
        labels: list[int] = []
        best: list[float] = []
        k = None if self.onset_frames is None else int(self.onset_frames)
        for a, b in segment_bounds(len(y), segments):
            slip = np.flatnonzero(y[a:b] == 1)
            onset = int(slip[0]) if len(slip) else b - a
            if onset > 0:
                labels.append(0)
                best.append(float(np.max(scores[a : a + onset])))
            if len(slip):
                labels.append(1)
                stop = b if k is None else min(b, a + onset + k)
                best.append(float(np.max(scores[a + onset : stop])))
        return np.asarray(labels, dtype=int), np.asarray(best)

    def _calibrate(
        self,
        X: FloatArray,
        y: NDArray[np.int_],
        scores: FloatArray,
        segments: ArrayLike | None,
    ) -> None:
        super()._calibrate(X, y, scores, segments)  # type: ignore[misc]
        if self.threshold is not None or self.calibration != "onset":
            return
        units, best = self.onset_units(y, scores, segments)
        pos, neg = best[units == 1], best[units == 0]
        if not len(pos) or not len(neg):
            return  # the sample ROC's choice stands
        # Youden's J = TPR - FPR at every candidate threshold (each unit score), then
        # the middle of the widest gap below an optimal candidate: every threshold in
        # (previous score, candidate] gives the same J.
        cand = np.unique(best[np.isfinite(best)])
        if not len(cand):
            return
        j = np.array([(pos >= c).mean() - (neg >= c).mean() for c in cand])
        below = np.concatenate([[-np.inf], cand[:-1]])
        top = np.flatnonzero(j == j.max())
        gaps = cand[top] - np.where(np.isfinite(below[top]), below[top], cand[top])
        i = int(top[np.argmax(gaps)])
        lo = below[i] if np.isfinite(below[i]) else cand[i]
        self.threshold_ = float(0.5 * (lo + cand[i]))
        finite = np.where(np.isfinite(scores), scores, np.finfo(np.float64).min)
        pred = finite >= self.threshold_
        self.tpr_ = float(pred[y == 1].mean()) if (y == 1).any() else float("nan")
        self.fnr_ = 1.0 - self.tpr_
        self.fpr_ = float(pred[y == 0].mean()) if (y == 0).any() else float("nan")
        self.tnr_ = 1.0 - self.fpr_


class ChannelChangeDetector(OnsetCalibration, StreamDetector):
    """Per-channel derivative or high-pass energy, scaled, combined over channels.

    Parameters
    ----------
    feature : {"derivative", "energy"}
        ``derivative``: ``(x[t] - x[t - span]) / span`` per channel (units per
        sample; any rate factor cancels in the scaled score, so the detector needs
        no rate); ``energy``: the RMS of that derivative over the last ``window``
        samples.
    span : int
        Samples of the backward difference.
    window : int
        Samples of the RMS (``energy`` only).
    polarity : {"abs", "learned"}
        ``derivative`` only: the absolute change (either direction is slip), or the
        change times a per-channel sign learned in ``fit`` (the sign of the mean
        derivative on slip samples minus that on non-slip samples).
    combine : {"max", "sum"}
        How the scaled channel scores make one score.
    calibration : {"onset", "sample"}
        How a free threshold is chosen (:class:`OnsetCalibration`): per-recording
        units mid-gap, or the per-sample ROC.
    onset_frames : int or None
        Samples from the onset that count as on time (None: the whole slip).
    threshold : float or None
        Slip when the score ``>= threshold`` (in non-slip spreads); None: chosen by
        ``calibration``.
    roc_point : {"youden", "closest"}
        ROC point of the per-sample ROC.

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
        "polarity": [StrOptions({"abs", "learned"})],
        "combine": [StrOptions({"max", "sum"})],
        "calibration": [StrOptions({"onset", "sample"})],
        "onset_frames": [Interval(Integral, 1, None, closed="left"), None],
    }
    n_channels: ClassVar[int | None] = None

    def __init__(
        self,
        *,
        feature: str = "derivative",
        span: int = 1,
        window: int = 10,
        polarity: str = "abs",
        combine: str = "max",
        calibration: str = "onset",
        onset_frames: int | None = None,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.feature = feature
        self.span = span
        self.window = window
        self.polarity = polarity
        self.combine = combine
        self.calibration = calibration
        self.onset_frames = onset_frames

    @property
    def window_samples(self) -> int:
        """Samples one score reads (the current one included)."""
        extra = int(self.window) - 1 if self.feature == "energy" else 0
        return int(self.span) + 1 + extra

    def _derivative(self, X: FloatArray) -> FloatArray:
        s = int(self.span)
        d = np.full(X.shape, np.nan)
        if len(X) > s:
            d[s:] = (X[s:] - X[:-s]) / s
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

    def _new_stream(self) -> RingStream:
        return RingStream(self)


__all__ = ["MIN_SCALE", "ChannelChangeDetector", "OnsetCalibration", "RingStream"]
