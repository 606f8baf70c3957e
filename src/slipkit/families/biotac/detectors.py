"""BioTac slip detectors of Su et al. 2015 (Humanoids, Sec. IV-B): AC-pressure vibration
and tangential-force derivative.

:class:`PressureVibration` -- the AC (hydro-acoustic) pressure at 2.2 kHz is band-passed
60-700 Hz (Butterworth, second-order sections), rectified, and slip is declared when at
least 11 of the last 22 samples (10 ms) exceed ``k`` times the baseline vibration (the
paper: ``k = 2``, the baseline being the vibration of the motors). The score is the
11th-largest rectified sample of the window divided by the baseline, so "``>= 11`` of 22
samples exceed ``k`` x baseline" is exactly "score ``>= k``": ``threshold_`` is ``k``
and the ROC over ``k`` is meaningful. The baseline is the RMS of the band-passed signal
over the first ``baseline_samples`` samples of each recording (a quiet stretch before the
object moves), or a fixed ``baseline`` in counts.

:class:`ForceDerivative` -- slip when ``dFt/dt < -0.5 N/s`` on the tangential force
``Ft = sqrt(Fx^2 + Fy^2)`` (300 Hz). The score is ``-dFt/dt`` (N/s), so ``threshold_`` is
0.5 by the paper. The paper does not say how it differentiates; the detector uses the
causal backward difference over ``span`` samples, ``(Ft[i] - Ft[i - span]) / (span /
rate_hz)``, which equals the mean of the last ``span`` one-sample differences: a
``span``-sample moving average of the derivative that damps sample noise (the paper's
``Ft`` is itself estimated from the electrodes) at the cost of ``(span - 1) / 2`` samples
of lag. Default ``span = 3`` (10 ms at 300 Hz, the pressure method's window).

NaN policy (both): a NaN sample scores ``-inf`` (never fires). The pressure detector
starts at the first finite sample of a recording (everything before scores ``-inf``) and
feeds the filter the last finite value in place of a later NaN (sample-and-hold), so one
dropped sample does not poison the filter state; the force derivative scores ``-inf``
wherever either end of its difference is NaN.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike
from scipy.signal import butter, sosfilt, sosfilt_zi
from sklearn.utils._param_validation import Interval

from slipkit.baselines.base import FloatArray, StreamDetector


class PressureVibration(StreamDetector):
    """AC-pressure vibration slip detector (Su et al. 2015, Sec. IV-B).

    Parameters
    ----------
    rate_hz : float
        AC-pressure sample rate (Hz); the BioTac: 2.2 kHz.
    band_hz : [low, high]
        Band-pass edges (Hz); the paper: 60-700 Hz.
    order : int
        Butterworth order per edge (the band-pass has ``2 order`` poles); the paper
        does not say, 4 gives ~48 dB/octave roll-off outside the band.
    window : int
        Samples per decision window; the paper: 22 (10 ms at 2.2 kHz).
    n_exceed : int
        Samples of the window that must exceed ``k`` x baseline; the paper: 11.
    baseline_samples : int
        Samples at the start of each recording whose band-passed RMS is the baseline
        vibration (default 220 = 0.1 s at 2.2 kHz); the detector is silent (score
        ``-inf``) until they are in. Ignored when ``baseline`` is set.
    baseline : float or None
        A fixed baseline vibration (counts RMS) instead of measuring it per recording.
    baseline_floor : float
        Smallest baseline (counts): one ADC step, so a silent (constant) start does not
        divide by zero.
    threshold : float or None
        ``k`` (multiple of the baseline); the paper: 2. None chooses it on the ROC.
    roc_point : {"youden", "closest"}
        ROC point chosen when ``threshold`` is None.

    Attributes
    ----------
    threshold_ : float
        ``k``.
    sos_ : ndarray (n_sections, 6)
        The band-pass filter.
    classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "band_hz": ["array-like"],
        "order": [Interval(Integral, 1, 10, closed="both")],
        "window": [Interval(Integral, 1, None, closed="left")],
        "n_exceed": [Interval(Integral, 1, None, closed="left")],
        "baseline_samples": [Interval(Integral, 1, None, closed="left")],
        "baseline": [Interval(Real, 0, None, closed="neither"), None],
        "baseline_floor": [Interval(Real, 0, None, closed="neither")],
    }
    n_channels: ClassVar[int | None] = 1

    def __init__(
        self,
        *,
        rate_hz: float = 2200.0,
        band_hz: Sequence[float] = (60.0, 700.0),
        order: int = 4,
        window: int = 22,
        n_exceed: int = 11,
        baseline_samples: int = 220,
        baseline: float | None = None,
        baseline_floor: float = 1.0,
        threshold: float | None = 2.0,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.rate_hz = rate_hz
        self.band_hz = band_hz
        self.order = order
        self.window = window
        self.n_exceed = n_exceed
        self.baseline_samples = baseline_samples
        self.baseline = baseline
        self.baseline_floor = baseline_floor

    def _design(self) -> FloatArray:
        lo, hi = (float(v) for v in self.band_hz)
        nyq = float(self.rate_hz) / 2.0
        if not 0.0 < lo < hi < nyq:
            raise ValueError(
                f"band_hz must satisfy 0 < low < high < rate_hz / 2 = {nyq:g} Hz; "
                f"got [{lo:g}, {hi:g}]"
            )
        if self.n_exceed > self.window:
            raise ValueError(
                f"n_exceed ({self.n_exceed}) cannot exceed window ({self.window})"
            )
        sos = butter(
            int(self.order), [lo, hi], btype="bandpass", fs=self.rate_hz, output="sos"
        )
        return np.asarray(sos, dtype=np.float64)

    @property
    def _sos(self) -> FloatArray:
        # Designed once in fit; during fit's own scoring it is already set.
        sos = getattr(self, "sos_", None)
        return self._design() if sos is None else np.asarray(sos)

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> PressureVibration:
        """Design the filter, then choose (or record) ``k`` on the ROC (see the base)."""
        self._validate_params()
        self.sos_ = self._design()
        super().fit(X, y, segments=segments)
        return self

    def _scores(self, X: FloatArray) -> FloatArray:
        x = X[:, 0]
        n = len(x)
        out = np.full(n, -np.inf)
        finite = np.isfinite(x)
        if not finite.any():
            return out
        f = int(np.argmax(finite))
        xs = x[f:]
        fin = finite[f:]
        # sample-and-hold over NaNs: index of the latest finite sample
        idx = np.maximum.accumulate(np.where(fin, np.arange(len(xs)), 0))
        xs = xs[idx]
        sos = self._sos
        zi = sosfilt_zi(sos) * xs[0]  # start in the steady state of the first value
        yf, _ = sosfilt(sos, xs, zi=zi)
        r = np.abs(yf)
        w, k = int(self.window), int(self.n_exceed)
        if self.baseline is not None:
            base, start = float(self.baseline), 0
        else:
            nb = int(self.baseline_samples)
            if len(r) < nb:
                return out
            # cumsum accumulates left to right, as the stream does
            base = math.sqrt(float(np.cumsum(yf[:nb] ** 2)[-1]) / nb)
            start = nb
        base = max(base, float(self.baseline_floor))
        start = max(start, w - 1)
        if len(r) <= start:
            return out
        win = sliding_window_view(r, w)  # row j = samples j .. j + w - 1
        kth = np.partition(win, w - k, axis=1)[:, w - k]  # the k-th largest
        s = np.full(len(r), -np.inf)
        s[start:] = kth[start - (w - 1) :] / base
        s[~fin] = -np.inf
        out[f:] = s
        return out

    def _new_stream(self) -> PressureStream:
        return PressureStream(self)


class PressureStream:
    """Sample-by-sample :class:`PressureVibration`: filter state, a ring of ``window``
    rectified samples and the baseline sum (O(1) in the recording length)."""

    def __init__(self, detector: PressureVibration) -> None:
        self._sos = detector._sos
        self._zi_unit = sosfilt_zi(self._sos)
        self._w = int(detector.window)
        self._k = int(detector.n_exceed)
        self._nb = int(detector.baseline_samples)
        self._fixed = None if detector.baseline is None else float(detector.baseline)
        self._floor = float(detector.baseline_floor)
        self._threshold = float(detector.threshold_)
        self.reset()

    def reset(self) -> None:
        """Forget the recording."""
        self._zi: FloatArray | None = None
        self._last = np.nan
        self._ring = np.zeros(self._w)
        self._j = 0  # samples since the first finite one
        self._ss = 0.0
        self._base = None if self._fixed is None else max(self._fixed, self._floor)

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        """Feed one AC-pressure sample (counts); return (k-th largest / baseline, slip)."""
        x = float(np.asarray(sample, dtype=np.float64).reshape(-1)[0])
        missing = not math.isfinite(x)
        if self._zi is None:
            if missing:
                return -np.inf, False
            self._zi = self._zi_unit * x
        if missing:
            x = self._last
        self._last = x
        yv, self._zi = sosfilt(self._sos, np.array([x]), zi=self._zi)
        yf = float(yv[0])
        j = self._j
        self._ring[j % self._w] = abs(yf)
        self._j += 1
        if self._fixed is None and j < self._nb:
            self._ss += yf * yf
            if j == self._nb - 1:
                self._base = max(math.sqrt(self._ss / self._nb), self._floor)
            return -np.inf, False
        if missing or j < self._w - 1 or self._base is None:
            return -np.inf, False
        kth = float(np.partition(self._ring, self._w - self._k)[self._w - self._k])
        score = kth / self._base
        return score, score >= self._threshold


class ForceDerivative(StreamDetector):
    """Tangential-force derivative slip detector (Su et al. 2015, Sec. IV-B).

    ``X`` holds ``(Fx, Fy)`` (N; ``Ft = sqrt(Fx^2 + Fy^2)``) or ``Ft`` alone.

    Parameters
    ----------
    rate_hz : float
        Force sample rate (Hz); the BioTac controller: 300 Hz.
    span : int
        Samples of the backward difference (see the module docstring); 3 = 10 ms.
    threshold : float or None
        Slip when ``-dFt/dt >= threshold`` (N/s); the paper: 0.5. None: ROC choice.
    roc_point : {"youden", "closest"}
        ROC point chosen when ``threshold`` is None.

    Attributes
    ----------
    threshold_ : float
        The fall rate of ``Ft`` that means slip (N/s).
    classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "span": [Interval(Integral, 1, None, closed="left")],
    }
    n_channels: ClassVar[int | None] = None  # Ft, or (Fx, Fy)

    def __init__(
        self,
        *,
        rate_hz: float = 300.0,
        span: int = 3,
        threshold: float | None = 0.5,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.rate_hz = rate_hz
        self.span = span

    def _check_X(self, X: ArrayLike, *, reset: bool) -> FloatArray:
        Xv = super()._check_X(X, reset=reset)
        if Xv.shape[1] not in (1, 2):
            raise ValueError(
                "ForceDerivative reads Ft (1 channel) or (Fx, Fy) (2 channels) per "
                f"sample; X has {Xv.shape[1]}"
            )
        return Xv

    def _scores(self, X: FloatArray) -> FloatArray:
        ft = X[:, 0] if X.shape[1] == 1 else np.hypot(X[:, 0], X[:, 1])
        out = np.full(len(ft), -np.inf)
        s = int(self.span)
        if len(ft) > s:
            d = -(ft[s:] - ft[:-s]) * (float(self.rate_hz) / s)
            out[s:] = np.where(np.isfinite(d), d, -np.inf)
        return out

    def _new_stream(self) -> ForceDerivativeStream:
        return ForceDerivativeStream(self)


class ForceDerivativeStream:
    """Sample-by-sample :class:`ForceDerivative`: a ring of the last ``span + 1`` Ft."""

    def __init__(self, detector: ForceDerivative) -> None:
        self._s = int(detector.span)
        self._per_s = float(detector.rate_hz) / self._s
        self._threshold = float(detector.threshold_)
        self.reset()

    def reset(self) -> None:
        """Forget the recording."""
        self._ring = np.full(self._s + 1, np.nan)
        self._i = 0

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        """Feed ``Ft`` or ``(Fx, Fy)`` (N); return (-dFt/dt in N/s, slip)."""
        f = np.asarray(sample, dtype=np.float64).reshape(-1)
        ft = float(f[0]) if len(f) == 1 else float(np.hypot(f[0], f[1]))
        i = self._i
        self._ring[i % (self._s + 1)] = ft
        self._i += 1
        if i < self._s:
            return -np.inf, False
        old = self._ring[(i - self._s) % (self._s + 1)]
        d = -(ft - old) * self._per_s
        if not math.isfinite(d):
            return -np.inf, False
        return d, d >= self._threshold


__all__ = [
    "ForceDerivative",
    "ForceDerivativeStream",
    "PressureStream",
    "PressureVibration",
]
