"""SlipTack acceleration from the nib deflection (eqs. 4 and 5): the batch estimator and its stream.

Part of the SlipTack baselines (:mod:`slipkit.families.sliptack.speed`, ``docs/families/sliptack.md``).
"""

from __future__ import annotations

import warnings
from collections import deque
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.linear_model import LinearRegression
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted, validate_data

from slipkit.baselines.base import segment_bounds
from slipkit.errors import TrainingDataError
from slipkit.families.sliptack.speed import (
    FixedNormalForceWarning,
    FloatArray,
    StickSlipSpeed,
)


# -- acceleration: eqs. 4 and 5 -----------------------------------------------------------
def _trailing_mean(x: FloatArray, k: int) -> FloatArray:
    """Mean of the last ``k`` samples (NaN before ``k`` samples exist)."""
    out = np.full(len(x), np.nan)
    if len(x) >= k:
        out[k - 1 :] = sliding_window_view(x, k).mean(axis=1)
    return out


def _slope(v: FloatArray, rate_hz: float) -> float:
    """Least-squares slope of ``v`` against time at ``rate_hz`` (units of v per s)."""
    t = (np.arange(len(v)) - 0.5 * (len(v) - 1)) / rate_hz
    return float(np.dot(t, v - v.mean()) / np.dot(t, t))


class DropAcceleration(RegressorMixin, BaseEstimator):
    """Acceleration of a sliding object from the nib signal (SlipTack eqs. 4 and 5).

    ``feature="deflection"`` (eq. 4, the paper's G): the gross deflection ``x - x0`` is
    the trailing mean of the nib signal over ``smooth_frames`` (mm; the mean removes the
    stick-slip ripple) and ``a = g - mu_k k_a (x - x0) / m_t`` is a line in it, fitted by
    linear regression (``fit``: intercept ~ ``g``, slope ~ ``-mu_k k_a / m_t``).
    ``feature="frequency_slope"`` (eq. 5, the paper's SF): the speed from
    :class:`StickSlipSpeed` (``speed`` parameters) and its least-squares slope over the
    last ``slope_frames`` samples (m/s^2), mapped to ``a`` by the same regression (the
    identity when eq. 5 holds).

    Parameters
    ----------
    feature : {"deflection", "frequency_slope"}
        Which signal feature eq. 4 / eq. 5 reads.
    rate_hz : float
        Nib stream rate (Hz).
    smooth_frames : int
        Trailing mean length for the gross deflection (frames).
    slope_frames : int
        Speed samples the frequency slope is fitted over (frames).
    speed : mapping, optional
        Parameters of the :class:`StickSlipSpeed` used by ``frequency_slope``.

    Attributes
    ----------
    coef_ : float
        Regression slope (m/s^2 per mm for ``deflection``; 1 per unit for the slope).
    intercept_ : float
        Regression intercept (m/s^2); ~ ``g`` for ``deflection``.
    r_ : float
        Pearson correlation of the feature with the true acceleration in ``fit``.
    speed_ : StickSlipSpeed or None
        The fitted speed estimator (``frequency_slope`` only).
    n_features_in_ : int
        Channels seen in ``fit`` (1).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "feature": [StrOptions({"deflection", "frequency_slope"})],
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "smooth_frames": [Interval(Integral, 1, None, closed="left")],
        "slope_frames": [Interval(Integral, 2, None, closed="left")],
        "speed": [dict, None],
    }

    def __init__(
        self,
        *,
        feature: str = "deflection",
        rate_hz: float = 1000.0,
        smooth_frames: int = 30,
        slope_frames: int = 50,
        speed: dict[str, Any] | None = None,
    ) -> None:
        self.feature = feature
        self.rate_hz = rate_hz
        self.smooth_frames = smooth_frames
        self.slope_frames = slope_frames
        self.speed = speed

    def _speed_estimator(self) -> StickSlipSpeed:
        params = {
            "rate_hz": self.rate_hz,
            "window": 200,
            "hop": 10,
            **(self.speed or {}),
        }
        return StickSlipSpeed(**params)

    def _recording_feature(self, x: FloatArray) -> FloatArray:
        if self.feature == "deflection":
            return _trailing_mean(x, int(self.smooth_frames))
        assert self.speed_ is not None
        # lenient: a drop shorter than the speed window has no slope (NaN), as before
        f = self.speed_._recording_frequency(x)
        v = self.speed_.speed_from_frequency(f) * 1e-3  # m/s
        k = int(self.slope_frames)
        out = np.full(len(x), np.nan)
        if len(x) >= k:
            out[k - 1 :] = [_slope(w, self.rate_hz) for w in sliding_window_view(v, k)]
        return out

    def _features(self, Xv: FloatArray, segments: ArrayLike | None) -> FloatArray:
        out = np.empty(len(Xv))
        for a, b in segment_bounds(len(Xv), segments):
            out[a:b] = self._recording_feature(Xv[a:b, 0])
        return out

    def _check(self, X: ArrayLike, *, reset: bool) -> FloatArray:
        Xv = np.asarray(
            validate_data(
                self, X, reset=reset, dtype=np.float64, ensure_all_finite=False
            )
        )
        if Xv.shape[1] != 1:
            raise ValueError(
                f"DropAcceleration reads 1 channel (the nib signal); X has {Xv.shape[1]}"
            )
        return Xv

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> DropAcceleration:
        """Calibrate the line ``a = intercept_ + coef_ * feature`` on true ``y`` (m/s^2).

        Samples with NaN ``y`` (outside the paper's window) or NaN feature are ignored.
        """
        self._validate_params()
        Xv = self._check(X, reset=True)
        yv = np.asarray(y, dtype=np.float64).reshape(-1)
        if yv.shape != (len(Xv),):
            raise ValueError(f"y must have shape ({len(Xv)},); got {yv.shape}")
        self.speed_: StickSlipSpeed | None = None
        if self.feature == "frequency_slope":
            # The speed law needs no calibration data: eq. 3 with the given physics.
            # The fixed-force warning does not apply: the regression below absorbs a
            # constant speed scale (a force off by a factor scales the slope by it).
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", FixedNormalForceWarning)
                self.speed_ = self._speed_estimator().fit(
                    np.zeros((1, 1)), np.full(1, np.nan)
                )
        feat = self._features(Xv, segments)
        ok = np.isfinite(feat) & np.isfinite(yv)
        if ok.sum() < 2 or np.ptp(feat[ok]) == 0:
            raise TrainingDataError(
                f"DropAcceleration({self.feature}): fewer than 2 distinct feature values "
                "with a true acceleration; cannot fit the calibration line (more "
                "training trials)"
            )
        reg = LinearRegression().fit(feat[ok, None], yv[ok])
        self.coef_ = float(reg.coef_[0])
        self.intercept_ = float(reg.intercept_)
        self.r_ = float(np.corrcoef(feat[ok], yv[ok])[0, 1])
        return self

    def transform_feature(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FloatArray:
        """The feature per sample (mm, or m/s^2 for the slope; NaN in the warm-up)."""
        check_is_fitted(self, "coef_")
        return self._features(self._check(X, reset=False), segments)

    def predict(self, X: ArrayLike, *, segments: ArrayLike | None = None) -> FloatArray:
        """Acceleration per sample (m/s^2, downward positive; NaN in the warm-up)."""
        return self.intercept_ + self.coef_ * self.transform_feature(
            X, segments=segments
        )

    def stream(self) -> AccelerationStream:
        """The sample-by-sample form: ``update(sample) -> acceleration`` (m/s^2)."""
        check_is_fitted(self, "coef_")
        return AccelerationStream(self)

    def __sklearn_tags__(self) -> Any:
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True
        return tags


class AccelerationStream:
    """Streaming :class:`DropAcceleration` over ring buffers (O(window) per sample)."""

    def __init__(self, est: DropAcceleration) -> None:
        self.est = est
        k = int(est.smooth_frames if est.feature == "deflection" else est.slope_frames)
        self.buf: deque[float] = deque(maxlen=k)
        self.speed = est.speed_.stream() if est.speed_ is not None else None

    def reset(self) -> None:
        """Forget all state (a new recording starts)."""
        self.buf.clear()
        if self.speed is not None:
            self.speed.reset()

    def update(self, sample: ArrayLike) -> float:
        """Feed one nib sample; return the acceleration estimate (m/s^2) or NaN."""
        x = float(np.asarray(sample, dtype=np.float64).reshape(-1)[0])
        if self.speed is None:
            self.buf.append(x)
        else:
            self.buf.append(self.speed.update(x)[1] * 1e-3)
        k = self.buf.maxlen or 1
        if len(self.buf) < k:
            return float("nan")
        w = np.fromiter(self.buf, np.float64, k)
        feat = (
            float(sliding_window_view(w, k).mean(axis=1)[0])
            if self.speed is None
            else _slope(w, self.est.rate_hz)
        )
        return self.est.intercept_ + self.est.coef_ * feat
