"""SlipTack slip onset from the nib's deflection rate: the coupled mode's fast path.

The SlipTack paper (seed 000, Sec. IV-E/V) arrests rapid slip sooner by coupling taxels
into one fast channel (~1 kHz) and reading the nib's deflection, not its stick-slip
frequency (which needs hundreds of frames). At a slip onset a nib sticks to the object
and is dragged with it until its breakaway (SlipTack eq. 1: stick while
``mu_s F_n >= k_l u``), so for the first ``mu_s F_n / (k_l v)`` seconds (33 ms at
100 mm/s, 330 ms at 10 mm/s for the simulated nib) the nib deflection ramps at the
object's own speed, ``u' = v``; in a drop (eq. 4) the object accelerates from rest and
the ramp bends upwards. Before the onset the stuck nib holds its deflection; the grip's
axial (gross) deflection only falls as fingers open, so the slip direction is the one
in which the signal rises.

:class:`SlipTackOnset` (analytic) scores the least-squares slope of the last ``window``
frames, in mm/s (signal units per second) times the slip direction's sign: the nib's
deflection rate, i.e. the object's speed while the nib sticks. One linear filter of
the window (:meth:`SlipTackOnset.weights`), exported as one ``MatMul``.

:class:`SlipTackOnsetLogistic` (learned) puts slopes over the last ``window / 4``,
``window / 2`` and ``window`` frames and the difference between the window's two
halves' slopes (the ramp bending: the drop's acceleration) into a logistic regression
trained for early decisions: positives are each training slip's first
``onset_frames`` frames, negatives every frame before an onset, the rest of a slip left
out. Every feature is linear in the window, so the logit is one linear filter plus a
bias (the scaler and the coefficients folded into :meth:`weights`).

Both choose a free threshold for early, correct decisions (``calibration="onset"``,
:class:`~slipkit.baselines.generic.OnsetCalibration`): each training recording's largest
score in its first ``onset_frames`` slip frames against its largest score before the
onset. ``docs/families/sliptack.md`` ("Onset detectors") states what they assume.
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from sklearn.linear_model import LogisticRegression
from sklearn.preprocessing import StandardScaler
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import FloatArray, StreamDetector, segment_bounds
from slipkit.baselines.generic import OnsetCalibration, RingStream
from slipkit.errors import TrainingDataError

#: Sign of each fixed direction (``"learned"`` is set by ``fit``).
DIRECTION_SIGN = {"rising": 1.0, "falling": -1.0}
#: The learned detector's features, in order.
FEATURES = ("slope_quarter", "slope_half", "slope_full", "bend")


def slope_weights(n: int, rate_hz: float) -> FloatArray:
    """Weights ``w`` (n,) with ``x @ w`` the least-squares slope of ``n`` samples
    ``x`` (oldest first) per second: ``(t - mean t) / sum (t - mean t)^2`` at ``rate_hz``."""
    if n < 2:
        raise ValueError(f"a slope needs at least 2 samples; got {n}")
    t = np.arange(n, dtype=np.float64)
    c = t - t.mean()
    return np.asarray(c / float(np.sum(c * c)) * float(rate_hz))


class SlipTackOnset(OnsetCalibration, StreamDetector):
    """Analytic SlipTack onset: the nib's deflection rate over ``window`` frames (module docstring).

    Parameters
    ----------
    rate_hz : float
        Frame rate (Hz); the coupled mode: 1 kHz.
    window : int
        Frames of the least-squares slope (at least 2).
    direction : {"learned", "rising", "falling"}
        The signal's slip direction: ``"learned"`` by ``fit`` (the sign of the mean
        slope on slip frames minus that on the others), or fixed.
    calibration : {"onset", "sample"}
        How ``fit`` chooses a free threshold
        (:class:`~slipkit.baselines.generic.OnsetCalibration`).
    onset_frames : int or None
        Frames from an onset that count as on time in the ``"onset"`` calibration
        (None: the whole slip).
    threshold : float or None
        The smallest deflection rate that is slip (signal units per second: mm/s for
        the nib); None: chosen by ``calibration``.
    roc_point : {"youden", "closest"}
        ROC point of the per-sample ROC.

    Attributes
    ----------
    sign_ : float
        +1 where the slip makes the signal rise, -1 where it falls.
    threshold_, classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "window": [Interval(Integral, 2, None, closed="left")],
        "direction": [StrOptions({"learned", "rising", "falling"})],
        "calibration": [StrOptions({"onset", "sample"})],
        "onset_frames": [Interval(Integral, 1, None, closed="left"), None],
    }
    n_channels: ClassVar[int | None] = 1

    def __init__(
        self,
        *,
        rate_hz: float = 1000.0,
        window: int = 10,
        direction: str = "learned",
        calibration: str = "onset",
        onset_frames: int | None = 20,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.rate_hz = rate_hz
        self.window = window
        self.direction = direction
        self.calibration = calibration
        self.onset_frames = onset_frames

    @property
    def window_samples(self) -> int:
        """Frames one score reads."""
        return int(self.window)

    def _raw_weights(self) -> FloatArray:
        """The unsigned slope filter (per second)."""
        return slope_weights(int(self.window), float(self.rate_hz))

    def weights(self) -> FloatArray:
        """``w`` (window,): the score of a window ``x`` (oldest first) is ``x @ w + bias()``."""
        return np.asarray(self.sign_ * self._raw_weights())

    def bias(self) -> float:
        """The score's constant term (0 for the slope)."""
        return 0.0

    def _learn_sign(
        self, X: FloatArray, y: NDArray[np.int_], segments: ArrayLike | None
    ) -> None:
        if self.direction != "learned":
            self.sign_ = DIRECTION_SIGN[str(self.direction)]
            return
        w = self._raw_weights()
        slopes = np.concatenate(
            [self._filter(X[a:b, 0], w) for a, b in segment_bounds(len(X), segments)]
        )
        ok = np.isfinite(slopes)
        pos, neg = ok & (y == 1), ok & (y == 0)
        if not pos.any() or not neg.any():
            raise TrainingDataError(
                f"{type(self).__name__}: direction 'learned' needs slip and non-slip "
                "frames in the training recordings (or set direction to 'rising' or "
                "'falling')"
            )
        gap = float(np.mean(slopes[pos]) - np.mean(slopes[neg]))
        self.sign_ = -1.0 if gap < 0 else 1.0

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> SlipTackOnset:
        """Learn the slip direction (``direction="learned"``), then choose ``threshold_``.

        See :meth:`StreamDetector.fit <slipkit.baselines.base.StreamDetector.fit>`.
        """
        self._validate_params()
        Xv = self._check_X(X, reset=True)
        yv = np.asarray(y).astype(int).reshape(-1)
        if yv.shape != (len(Xv),):
            raise ValueError(f"y must have shape ({len(Xv)},); got {yv.shape}")
        self._learn_sign(Xv, yv, segments)
        self._fit_model(Xv, yv, segments)
        super().fit(Xv, yv, segments=segments)
        return self

    def _fit_model(
        self, X: FloatArray, y: NDArray[np.int_], segments: ArrayLike | None
    ) -> None:
        """Learned detectors fit their model here (after the sign, before the threshold)."""

    @staticmethod
    def _filter(x: FloatArray, w: FloatArray, bias: float = 0.0) -> FloatArray:
        """``x[i-W+1..i] @ w + bias`` at every frame ``i`` of one recording (NaN in warm-up)."""
        n, k = len(x), len(w)
        out = np.full(n, np.nan)
        if n >= k:
            out[k - 1 :] = sliding_window_view(x, k) @ w + bias
        return out

    def _scores(self, X: FloatArray) -> FloatArray:
        s = self._filter(X[:, 0], self.weights(), self.bias())
        return np.where(np.isfinite(s), s, -np.inf)

    def _new_stream(self) -> RingStream:
        return RingStream(self)


class SlipTackOnsetLogistic(SlipTackOnset):
    """Learned SlipTack onset: multi-scale slopes and the ramp's bend -> logistic regression.

    Parameters
    ----------
    C : float
        Inverse regularisation of the logistic regression.
    rate_hz, window, direction, calibration, onset_frames, threshold, roc_point
        As :class:`SlipTackOnset` (``window`` at least 8: its quarter is a slope);
        ``threshold`` is a logit.

    Attributes
    ----------
    coef_ : ndarray (4,)
        Logistic coefficients of :data:`FEATURES` in raw feature units (the scaler
        folded in).
    intercept_ : float
        Its intercept.
    """

    #: shown as a learned estimator in comparisons (it fits a logistic regression)
    slipkit_kind = "learned"

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **SlipTackOnset._parameter_constraints,
        "window": [Interval(Integral, 8, None, closed="left")],
        "C": [Interval(Real, 0, None, closed="neither")],
    }

    def __init__(
        self,
        *,
        rate_hz: float = 1000.0,
        window: int = 20,
        direction: str = "learned",
        calibration: str = "onset",
        onset_frames: int | None = 20,
        C: float = 1.0,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(
            rate_hz=rate_hz,
            window=window,
            direction=direction,
            calibration=calibration,
            onset_frames=onset_frames,
            threshold=threshold,
            roc_point=roc_point,
        )
        self.C = C

    def feature_matrix(self) -> FloatArray:
        """``(window, 4)``: the window (oldest first) times it gives :data:`FEATURES`
        (signed by ``sign_``, per second)."""
        w, rate = int(self.window), float(self.rate_hz)
        cols = np.zeros((w, 4))
        for j, n in enumerate((max(2, w // 4), max(2, w // 2), w)):
            cols[w - n :, j] = slope_weights(n, rate)
        h = w // 2
        cols[w - h :, 3] += slope_weights(h, rate)
        cols[w - 2 * h : w - h, 3] -= slope_weights(h, rate)
        return np.asarray(self.sign_ * cols)

    def _fit_model(
        self, X: FloatArray, y: NDArray[np.int_], segments: ArrayLike | None
    ) -> None:
        m = self.feature_matrix()
        feats, labels = [], []
        k = None if self.onset_frames is None else int(self.onset_frames)
        for a, b in segment_bounds(len(X), segments):
            x = X[a:b, 0]
            if len(x) < len(m):
                continue
            f = np.full((len(x), 4), np.nan)
            f[len(m) - 1 :] = sliding_window_view(x, len(m)) @ m
            slip = np.flatnonzero(y[a:b] == 1)
            onset = int(slip[0]) if len(slip) else len(x)
            lab = np.full(len(x), -1)
            lab[:onset] = 0
            stop = len(x) if k is None else min(len(x), onset + k)
            lab[onset:stop] = np.where(y[a:b][onset:stop] == 1, 1, -1)
            keep = (lab >= 0) & np.isfinite(f).all(axis=1)
            feats.append(f[keep])
            labels.append(lab[keep])
        F = np.vstack(feats) if feats else np.empty((0, 4))
        L = np.concatenate(labels) if labels else np.empty(0, dtype=int)
        if len(np.unique(L)) < 2:
            raise TrainingDataError(
                f"{type(self).__name__}: needs frames before and just after a slip "
                "onset in the training recordings"
            )
        scaler = StandardScaler().fit(F)
        clf = LogisticRegression(C=float(self.C), class_weight="balanced")
        clf.fit(scaler.transform(F), L)
        scale = np.where(scaler.scale_ > 0, scaler.scale_, 1.0)
        self.coef_ = np.asarray(clf.coef_[0] / scale)
        self.intercept_ = float(clf.intercept_[0] - np.sum(self.coef_ * scaler.mean_))

    def weights(self) -> FloatArray:
        """``w`` (window,): the logit of a window ``x`` is ``x @ w + bias()``."""
        check_is_fitted(self, "coef_")
        return np.asarray(self.feature_matrix() @ self.coef_)

    def bias(self) -> float:
        """The logit's intercept."""
        check_is_fitted(self, "coef_")
        return float(self.intercept_)


__all__ = [
    "DIRECTION_SIGN",
    "FEATURES",
    "SlipTackOnset",
    "SlipTackOnsetLogistic",
    "slope_weights",
]
