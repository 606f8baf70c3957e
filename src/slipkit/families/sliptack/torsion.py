"""SlipTack torsional slip: the RMS of the nib signal in the ~10 Hz band (a stream detector).

Part of the SlipTack baselines (:mod:`slipkit.families.sliptack.speed`, ``docs/families/sliptack.md``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike
from scipy.signal import butter, sosfilt, sosfilt_zi
from sklearn.utils._param_validation import Interval

from slipkit.baselines.base import DetectorStream, StreamDetector
from slipkit.families.sliptack.speed import FloatArray


# -- torsional slip: the ~10 Hz band ----------------------------------------------------------
class TorsionalSlipDetector(StreamDetector):
    """Torsional slip flag: RMS of the nib signal in the ~10 Hz band (SlipTack Sec. IV-F).

    The paper detects torsional slip from the sensor's "effective frequency response
    ~10 Hz" without giving the rule; slipkit band-passes the signal (Butterworth,
    ``scipy.signal``, second-order sections, causal) and scores each sample by the RMS of
    the band over the last ``window`` samples (signal unit, e.g. mm). The threshold comes
    from the ROC (``threshold=None``) or is fixed.

    Parameters
    ----------
    rate_hz : float
        Stream rate (Hz).
    band_hz : (float, float)
        Pass band (Hz).
    order : int
        Butterworth order (per band edge).
    window : int
        RMS window (frames).
    threshold, roc_point
        As in :class:`~slipkit.baselines.base.StreamDetector`.

    Attributes
    ----------
    threshold_, classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_
        As in :class:`~slipkit.baselines.base.StreamDetector`.
    n_features_in_ : int
        Channels seen in ``fit`` (1).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "band_hz": ["array-like"],
        "order": [Interval(Integral, 1, None, closed="left")],
        "window": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(
        self,
        *,
        rate_hz: float = 1000.0,
        band_hz: Sequence[float] = (5.0, 15.0),
        order: int = 2,
        window: int = 100,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.rate_hz = rate_hz
        self.band_hz = band_hz
        self.order = order
        self.window = window

    def _sos(self) -> FloatArray:
        lo, hi = (float(b) for b in self.band_hz)
        if not 0 < lo < hi < self.rate_hz / 2:
            raise ValueError(
                f"band_hz must satisfy 0 < lo < hi < rate_hz / 2; got {self.band_hz}"
            )
        return np.asarray(
            butter(
                self.order, [lo, hi], btype="bandpass", fs=self.rate_hz, output="sos"
            )
        )

    def _scores(self, X: FloatArray) -> FloatArray:
        x = X[:, 0]
        out = np.full(len(x), -np.inf)
        finite = np.isfinite(x)
        if not finite.any():
            return out
        f = int(np.argmax(finite))
        xs = x[f:]
        # A dropped (NaN) sample holds the last deflection: no change, no band energy.
        # (Zero would be a step from the resting deflection to 0 mm and ring the filter.)
        xs = xs[np.maximum.accumulate(np.where(np.isfinite(xs), np.arange(len(xs)), 0))]
        sos = self._sos()
        # Start in the steady state of the first sample: a nib resting at any
        # deflection has no 10 Hz content, so the filter must not ring at start-up.
        band, _ = sosfilt(sos, xs, zi=sosfilt_zi(sos) * xs[0])
        k = int(self.window)
        if len(xs) >= k:
            out[f + k - 1 :] = np.sqrt(sliding_window_view(band * band, k).mean(axis=1))
        return out

    def _new_stream(self) -> DetectorStream:
        return _BandStream(self)


class _BandStream:
    def __init__(self, det: TorsionalSlipDetector) -> None:
        self.det = det
        self.sos = det._sos()
        self.reset()

    def reset(self) -> None:
        self.zi: FloatArray | None = None  # set by the first finite sample
        self.last = math.nan
        self.buf: deque[float] = deque(maxlen=int(self.det.window))

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        x = float(np.asarray(sample, dtype=np.float64).reshape(-1)[0])
        if not math.isfinite(x):  # dropped: hold the last deflection, as the batch form
            if self.zi is None:
                return -np.inf, False
            x = self.last
        if self.zi is None:
            self.zi = sosfilt_zi(self.sos) * x
        self.last = x
        y, self.zi = sosfilt(self.sos, [x], zi=self.zi)
        self.buf.append(float(y[0]) ** 2)
        k = int(self.det.window)
        if len(self.buf) < k:
            return -np.inf, False
        w = np.fromiter(self.buf, np.float64, k)
        score = float(np.sqrt(sliding_window_view(w, k).mean(axis=1)[0]))
        return score, score >= self.det.threshold_
