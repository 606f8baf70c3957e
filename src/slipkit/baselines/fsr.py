"""FSR touch-and-slip detector (Gentile, Cordella, Ramos Rodrigues, Zollo 2020).

Three stages on the conditioned FSR voltage sampled at 2 kHz (paper Sec. 2.3, Fig. 2):

1. **touch** -- ``v_rest`` is the mean of the first ``rest_samples`` (10) samples of the
   recording (the paper's calibration period, no force on the sensor); a block of
   samples is *touched* when ``v_rest - v_mean > delta`` (eqs. 2-3);
2. **derivative** -- ``v_mean`` is the mean of each block of ``block`` (5) samples
   (eq. 1) and ``v'_mean = (v_mean(i) - v_mean(i-1)) / cycle_time`` its backward
   difference (eq. 4), the cycle time being the block period ``block / rate_hz``
   (2.5 ms at 2 kHz), so ``v'_mean`` is in V/s;
3. **slip** -- ``slip = 1`` when ``v'_mean >= alpha`` (eq. 5). Only one sign counts: a
   rising voltage (a pressure release) for ``input="voltage"``, a falling force for
   ``input="force"`` (the force comes from the eq. 6 polynomial,
   :func:`slipkit.physics.fsr.force_from_voltage`), so the press of a touch is never slip.

``alpha`` is :attr:`threshold_`, chosen on the ROC by ``fit`` (the paper: ROC over 30
induced slips, ``alpha = 8``; the text prints no unit, eq. 4 makes it V/s) or fixed.

Block and sample timing (batch and streaming agree exactly). Blocks are aligned to the
first sample of the recording: block ``b`` holds samples ``5b .. 5b + 4`` and its
decision is made at its last sample ``5b + 4``. A sample's score is the score of the
latest completed block, held until the next one completes (a trailing incomplete block
holds the previous score). The first decided block is the first one after the rest
period (block 2 for 10 rest samples and 5-sample blocks, decided at sample 14); every
earlier sample scores ``-inf`` (warm-up). An untouched block scores ``-inf`` too: the
paper's slip stage only runs after a touch (Fig. 2).

NaN policy: a non-finite sample makes its block mean NaN, so that block and the next
score ``-inf`` (no decision on missing data); the rest mean averages the finite samples
of the rest period (all of them missing: no touch is ever seen).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import FloatArray, StreamDetector, segment_bounds
from slipkit.physics.fsr import DEFAULT_CALIBRATION

#: ``delta`` when not given, per input: a 0.2 V drop is a ~0.1 N press with the default
#: calibration (200x the 1 mV conditioning noise, below the FSR 402's 0.2 N threshold).
DEFAULT_DELTA = {"voltage": 0.2, "force": 0.1}


def _sequential_sum(values: Sequence[float]) -> float:
    # Plain left-to-right sum (not numpy's pairwise one) so batch and streaming
    # round identically.
    total = 0.0
    for v in values:
        total += v
    return total


class FSRTouchSlip(StreamDetector):
    """Gentile et al. 2020 touch-and-slip detector on one FSR channel.

    Parameters
    ----------
    input : {"voltage", "force"}
        What ``X`` holds: the conditioned voltage (V; slip = rising voltage) or, for
        ``"force"``, the same voltage converted to force (N) by ``calibration`` inside
        the detector (slip = falling force). Either way ``X`` is the voltage column.
    rate_hz : float
        Sample rate (Hz); the paper: 2 kHz.
    block : int
        Samples per mean (eq. 1); the paper: 5.
    rest_samples : int
        Samples at the start of each recording averaged into ``v_rest``; the paper: 10.
    delta : float or None
        Touch threshold on ``v_rest - v_mean`` (V) or ``F_mean - F_rest`` (N). None:
        0.2 V / 0.1 N (:data:`DEFAULT_DELTA`), a ~0.1 N press with the default
        calibration, far above the noise.
    calibration : sequence of 5 floats or None
        ``p1..p5`` of eq. 6 (N from V) for ``input="force"``; None: the default
        :data:`slipkit.physics.fsr.DEFAULT_CALIBRATION`.
    threshold : float or None
        ``alpha`` in V/s (N/s for force); None chooses it on the ROC in ``fit``.
    roc_point : {"youden", "closest"}
        ROC point chosen when ``threshold`` is None.

    Attributes
    ----------
    threshold_ : float
        ``alpha`` (V/s, or N/s for force input).
    delta_ : float
        The touch threshold used (V or N).
    classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "input": [StrOptions({"voltage", "force"})],
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "block": [Interval(Integral, 1, None, closed="left")],
        "rest_samples": [Interval(Integral, 1, None, closed="left")],
        "delta": [Interval(Real, 0, None, closed="left"), None],
        "calibration": ["array-like", None],
    }
    n_channels: ClassVar[int | None] = 1

    def __init__(
        self,
        *,
        input: str = "voltage",
        rate_hz: float = 2000.0,
        block: int = 5,
        rest_samples: int = 10,
        delta: float | None = None,
        calibration: Sequence[float] | None = None,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.input = input
        self.rate_hz = rate_hz
        self.block = block
        self.rest_samples = rest_samples
        self.delta = delta
        self.calibration = calibration

    # -- settings -----------------------------------------------------------------
    @property
    def _sign(self) -> float:
        # +1: a rising voltage is a pressure release; -1: a falling force is.
        return 1.0 if self.input == "voltage" else -1.0

    @property
    def _delta(self) -> float:
        return float(DEFAULT_DELTA[self.input] if self.delta is None else self.delta)

    @property
    def _first_block(self) -> int:
        # The first block wholly after the rest period (and with a predecessor).
        return max(1, math.ceil(self.rest_samples / self.block))

    @property
    def _per_s(self) -> float:
        # 1 / cycle time: the block period is block / rate_hz seconds.
        return float(self.rate_hz) / int(self.block)

    def _coeffs(self) -> FloatArray:
        cal = DEFAULT_CALIBRATION if self.calibration is None else self.calibration
        p = np.asarray(cal, dtype=np.float64).reshape(-1)
        if p.shape != (5,):
            raise ValueError(
                f"calibration must list 5 coefficients p1..p5 (eq. 6); got {p.tolist()}"
            )
        return p

    def _signal(self, v: FloatArray) -> FloatArray:
        if self.input == "voltage":
            return v
        return np.asarray(np.polyval(self._coeffs(), v), dtype=np.float64)

    def _calibrate(
        self,
        X: FloatArray,
        y: Any,
        scores: FloatArray,
        segments: ArrayLike | None,
    ) -> None:
        self.delta_ = self._delta
        super()._calibrate(X, y, scores, segments)

    # -- batch ----------------------------------------------------------------------
    def _block_stats(self, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(derivative, press) of every complete block of one recording; NaN before
        the first decided block. ``press`` is ``v_rest - v_mean`` (V) or
        ``F_mean - F_rest`` (N)."""
        b, nb = int(self.block), len(v) // int(self.block)
        blocks = v[: nb * b].reshape(nb, b)
        acc = np.zeros(nb)
        for j in range(b):  # left to right, as the stream adds samples
            acc = acc + blocks[:, j]
        means = acc / b
        deriv, press = np.full(nb, np.nan), np.full(nb, np.nan)
        first = self._first_block
        if nb > first:
            head = v[: self.rest_samples]
            finite = head[np.isfinite(head)].tolist()
            rest = _sequential_sum(finite) / len(finite) if finite else np.nan
            m = means[first:]
            deriv[first:] = self._sign * (m - means[first - 1 : -1]) * self._per_s
            press[first:] = self._sign * (rest - m)
        return deriv, press

    def _per_sample(self, per_block: FloatArray, n: int, fill: float) -> FloatArray:
        """Hold each block's value from its last sample until the next block ends."""
        bl = int(self.block)
        b = (np.arange(n) - (bl - 1)) // bl  # latest completed block (-1: none)
        out = np.full(n, fill)
        valid = b >= self._first_block
        out[valid] = per_block[b[valid]]
        return out

    def _scores(self, X: FloatArray) -> FloatArray:
        deriv, press = self._block_stats(self._signal(X[:, 0]))
        with np.errstate(invalid="ignore"):
            ok = (press > self._delta) & np.isfinite(deriv)
        return self._per_sample(np.where(ok, deriv, -np.inf), len(X), -np.inf)

    def touch(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> NDArray[np.bool_]:
        """Stage 1 per sample: touched at the latest completed block (fitted detector)."""
        check_is_fitted(self, "threshold_")
        Xv = self._check_X(X, reset=False)
        out = np.zeros(len(Xv), dtype=bool)
        for a, z in segment_bounds(len(Xv), segments):
            _, press = self._block_stats(self._signal(Xv[a:z, 0]))
            with np.errstate(invalid="ignore"):
                touched = (press > self._delta).astype(np.float64)
            out[a:z] = self._per_sample(touched, z - a, 0.0) > 0
        return out

    # -- streaming ------------------------------------------------------------------
    def _new_stream(self) -> FSRStream:
        return FSRStream(self)


class FSRStream:
    """Sample-by-sample :class:`FSRTouchSlip` (O(1) state: sums, one mean, one score).

    Attributes
    ----------
    touched : bool
        Stage 1 at the latest completed block.
    """

    def __init__(self, detector: FSRTouchSlip) -> None:
        self._force = detector.input == "force"
        self._coeffs = detector._coeffs() if self._force else None
        self._sign = detector._sign
        self._delta = detector._delta
        self._block = int(detector.block)
        self._rest_n = int(detector.rest_samples)
        self._first = detector._first_block
        self._per_s = detector._per_s
        self._threshold = float(detector.threshold_)
        self.reset()

    def reset(self) -> None:
        """Forget the recording (rest mean, block sums, score)."""
        self._i = 0
        self._rest_sum, self._rest_cnt = 0.0, 0
        self._acc, self._k = 0.0, 0
        self._prev = np.nan
        self._score = -np.inf
        self.touched = False

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        """Feed one voltage sample (V); return (score in V/s or N/s, slip)."""
        v = float(np.asarray(sample, dtype=np.float64).reshape(-1)[0])
        if self._coeffs is not None:
            v = float(np.polyval(self._coeffs, v))
        if self._i < self._rest_n and math.isfinite(v):
            self._rest_sum += v
            self._rest_cnt += 1
        self._acc += v
        self._k += 1
        if self._k == self._block:
            mean = self._acc / self._block
            if self._i // self._block >= self._first:
                rest = self._rest_sum / self._rest_cnt if self._rest_cnt else np.nan
                deriv = self._sign * (mean - self._prev) * self._per_s
                self.touched = bool(self._sign * (rest - mean) > self._delta)
                ok = self.touched and math.isfinite(deriv)
                self._score = deriv if ok else -np.inf
            self._prev = mean
            self._acc, self._k = 0.0, 0
        self._i += 1
        return self._score, self._score >= self._threshold


__all__ = ["DEFAULT_DELTA", "FSRStream", "FSRTouchSlip"]
