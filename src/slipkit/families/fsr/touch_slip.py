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
   :func:`slipkit.families.fsr.physics.force_from_voltage`), so the press of a touch is never slip.

``alpha`` is :attr:`threshold_`, chosen on the ROC by ``fit`` (an alpha equal to a
training score, as a ROC choice is, moves halfway down to the next lower training score,
so that a repeated score of a quantised signal is never exactly on it) (the paper: ROC over 30
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

**Polarity (the wiring convention, checked).** The paper's divider makes the voltage
*fall* as the force rises; the other common wiring makes it *rise*. ``polarity`` says
which (``"falling"``, ``"rising"``) or, with ``"auto"`` (the default), ``fit`` learns it
from the training recordings: every recording's samples that leave its rest mean by more
than ``delta`` vote for the direction they moved (a press); recordings of both wirings
give ``"per_recording"`` (each recording's first block further than ``delta`` from its
rest sets its direction) with a :class:`PolarityWarning`. Training data in which no recording is ever pressed is refused
(:class:`~slipkit.errors.SlipkitError` naming the data), also with a fixed threshold:
with an unknown polarity the detector would otherwise look at the wrong sign and
silently never fire. Slip is the opposite of a press: a voltage moving back towards
rest (rising for ``"falling"``, falling for ``"rising"``), a falling force. For
``input="force"`` the calibration must turn a press into a rising force; a calibration
that does not match the wiring is refused. ``fit`` also records ``rest_V_``, the median
rest voltage of the training recordings, the constant the ONNX graph's touch gate uses
for force input. For voltage input the deployed detector takes each stream's rest level
on the gripper PC, as this class takes each recording's: the runtime op ``press_sign``
(:mod:`slipkit.runtime.preprocessing`) with the fitted sign or, with
``"per_recording"``, the sign latched at the first press as this class does, and the
graph reads the sign-normalised signal
(:func:`slipkit.families.fsr.export.touch_slip.export_fsr_touch_slip`).

**Confirmation (``confirm_events``, a slipkit addition against impulsive bumps).** One
sharp external bump (tens of % of the holding force in a millisecond) gives one large
derivative, as large as a slip event's; a slide is a *train* of stick-slip events. With
``confirm_events = k >= 2`` a block's derivative counts as an *event* when it is a peak
(larger than the ``peak_gap_s`` before it, at least as large as the ``peak_gap_s`` after
it, so it is confirmed ``peak_gap_s`` later; derivatives within :data:`PEAK_TIE` x blocks
per second of each other count as equal, so float32 rounding never moves a peak), and
the score is the ``k``-th largest event
within the last ``confirm_window_s``: ``score >= alpha`` means "at least ``k`` separate
events of at least ``alpha`` within the window". ``k = 1`` (the default) is the paper's
detector exactly. The ``fsr_robust`` config uses ``k = 3`` over 0.4 s.
"""

from __future__ import annotations

import math
import warnings
from collections import deque
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import FloatArray, StreamDetector, segment_bounds
from slipkit.errors import SlipkitError, SlipkitWarning
from slipkit.families.fsr.physics import DEFAULT_CALIBRATION

#: The voltage direction under a press for each wiring: -1 falls (the paper), +1 rises.
PRESS_DIRECTION = {"falling": -1.0, "rising": 1.0}


class PolarityWarning(SlipkitWarning):
    """Training recordings of both wirings: the detector sets the sign per recording."""


#: ``delta`` when not given, per input: a 0.2 V drop is a ~0.1 N press with the default
#: calibration (200x the 1 mV conditioning noise, below the FSR 402's 0.2 N threshold).
DEFAULT_DELTA = {"voltage": 0.2, "force": 0.1}

#: Block-mean step (V, or N for force input) below which two block derivatives count as
#: equal in the peak test of ``confirm_events > 1``. A quantised signal (an ADC) gives
#: exactly equal derivatives often; the deployed graph reads float32 samples (a 5 V
#: sample is off by up to 0.3 uV), so an exact ``>`` would break such ties at random
#: and move a peak to the next block. 10 uV is 30x that rounding and 1 % of the 1 mV
#: conditioning noise; times the blocks per second it is the tolerance in V/s.
PEAK_TIE = 1e-5


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
        :data:`slipkit.families.fsr.physics.DEFAULT_CALIBRATION`.
    polarity : {"auto", "falling", "rising", "per_recording"}
        How the conditioned voltage moves when the FSR is pressed: ``"falling"`` (the
        paper's divider), ``"rising"`` (the other common wiring), ``"per_recording"``
        (each recording's first press sets its direction; voltage input; deployed
        with the runtime op ``press_sign`` before the graph), or ``"auto"``: learned by ``fit`` from the training recordings (which
        must include a press; recordings of both wirings give ``"per_recording"`` and a
        :class:`PolarityWarning`).
    confirm_events : int
        Separate derivative peaks of at least ``alpha`` needed within
        ``confirm_window_s`` to declare slip; 1 is the paper's detector (one block).
    confirm_window_s : float
        Window (s) in which ``confirm_events`` peaks must fall (``confirm_events >= 2``).
    peak_gap_s : float
        A block's derivative is a peak when it exceeds every block in the
        ``peak_gap_s`` (s) before it and is not exceeded in the ``peak_gap_s`` after
        it (one bump's edge spans a few blocks and gives one peak); a peak is known
        ``peak_gap_s`` after its block.
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
    polarity_ : {"falling", "rising", "per_recording"}
        The voltage direction under a press (given, or learned in ``fit``).
    polarity_votes_ : dict
        Training recordings whose press fell / rose / that were never pressed
        (``{"falling": n, "rising": n, "untouched": n}``).
    rest_V_ : float
        Median over the training recordings of the rest voltage (V): the mean of each
        recording's first ``rest_samples`` finite samples (NaN if none).
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
        "polarity": [StrOptions({"auto", "falling", "rising", "per_recording"})],
        "confirm_events": [Interval(Integral, 1, None, closed="left")],
        "confirm_window_s": [Interval(Real, 0, None, closed="neither")],
        "peak_gap_s": [Interval(Real, 0, None, closed="neither")],
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
        polarity: str = "auto",
        confirm_events: int = 1,
        confirm_window_s: float = 0.3,
        peak_gap_s: float = 0.01,
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
        self.polarity = polarity
        self.confirm_events = confirm_events
        self.confirm_window_s = confirm_window_s
        self.peak_gap_s = peak_gap_s

    # -- settings -----------------------------------------------------------------
    @property
    def _polarity(self) -> str:
        known = getattr(self, "polarity_", None)
        if known is not None:
            return str(known)
        if self.polarity == "auto":
            raise SlipkitError(
                "FSRTouchSlip: polarity 'auto' is learned by fit from recordings that "
                "include a press; call fit, or set polarity to 'falling' (voltage falls "
                "with force, the paper) or 'rising'"
            )
        return str(self.polarity)

    @property
    def _sign(self) -> float:
        # The slip direction of the signal the detector reads: the opposite of a press.
        # Voltage: +1 (rising) for the paper's falling wiring, -1 for a rising one;
        # force (the calibration makes a press a rising force): -1.
        if self.input == "force":
            return -1.0
        polarity = self._polarity
        if polarity == "per_recording":
            raise SlipkitError(
                "FSRTouchSlip(polarity='per_recording'): the slip sign is set per "
                "recording by its first press; there is no single sign (one fixed wiring "
                "needs polarity 'falling' or 'rising')"
            )
        return -PRESS_DIRECTION[polarity]

    @property
    def _peak_gap(self) -> int:
        # blocks a peak must dominate on each side (at least one)
        return max(1, math.ceil(float(self.peak_gap_s) * self._per_s - 1e-9))

    @property
    def _peak_tie(self) -> float:
        # derivatives (V/s or N/s) closer than this are equal in the peak test
        return PEAK_TIE * self._per_s

    @property
    def _confirm_blocks(self) -> int:
        # blocks of the confirmation window (at least confirm_events)
        return max(
            int(self.confirm_events), round(float(self.confirm_window_s) * self._per_s)
        )

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

    def _rest_means(self, v: FloatArray, segments: ArrayLike | None) -> list[float]:
        """Rest mean (V) of every recording (NaN without a finite rest sample)."""
        out = []
        for a, z in segment_bounds(len(v), segments):
            head = v[a:z][: int(self.rest_samples)]
            finite = head[np.isfinite(head)]
            out.append(float(np.mean(finite)) if finite.size else math.nan)
        return out

    def _learn_polarity(self, v: FloatArray, segments: ArrayLike | None) -> None:
        """Set ``polarity_``, ``polarity_votes_`` and ``rest_V_`` from voltages ``v``."""
        # The press is found on the voltage with a voltage threshold: delta for
        # voltage input, or the default 0.2 V for force input (its delta is in N).
        dv = (
            float(self.delta)
            if self.input == "voltage" and self.delta is not None
            else (DEFAULT_DELTA["voltage"])
        )
        votes = {"falling": 0, "rising": 0, "untouched": 0}
        voted: dict[str, list[int]] = {"falling": [], "rising": []}
        rests = self._rest_means(v, segments)
        for k, ((a, z), rest) in enumerate(
            zip(segment_bounds(len(v), segments), rests, strict=True)
        ):
            dev = v[a + int(self.rest_samples) : z] - rest
            with np.errstate(invalid="ignore"):
                up, down = int(np.sum(dev > dv)), int(np.sum(dev < -dv))
            if up == down == 0:
                votes["untouched"] += 1
                continue
            side = "rising" if up > down else "falling"
            votes[side] += 1
            voted[side].append(k)
        self.polarity_votes_ = votes
        finite = [r for r in rests if math.isfinite(r)]
        self.rest_V_ = float(np.median(finite)) if finite else math.nan
        n = len(rests)
        if self.polarity != "auto":
            self.polarity_ = str(self.polarity)
        elif votes["falling"] == votes["rising"] == 0:
            raise SlipkitError(
                f"FSRTouchSlip(polarity='auto'): the training data ({n} recording(s), "
                f"{len(v)} samples) never shows a touch -- no sample moves more than "
                f"{dv:g} V from its recording's rest mean (first {self.rest_samples} "
                "samples), so the press direction cannot be learned; fit on recordings "
                "that start at rest and include a press, or set polarity to 'falling' "
                "(voltage falls with force, the paper's divider) or 'rising'"
            )
        elif votes["falling"] and votes["rising"]:
            warnings.warn(
                "FSRTouchSlip(polarity='auto'): the training recordings disagree on the "
                f"press direction: recordings {voted['falling'][:10]} fall, "
                f"{voted['rising'][:10]} rise under a press (0-based, in segment order); "
                "using polarity 'per_recording' (each recording's first press sets its "
                "sign; deployed with the runtime's press_sign op). Set polarity to "
                "silence this",
                PolarityWarning,
                stacklevel=3,
            )
            self.polarity_ = "per_recording"
        else:
            self.polarity_ = "falling" if votes["falling"] else "rising"
        if self.polarity_ == "per_recording" and self.input == "force":
            raise SlipkitError(
                "FSRTouchSlip(input='force'): one calibration cannot serve recordings of "
                f"both wirings (votes {votes}); fit one detector per wiring, or use "
                "input='voltage'"
            )
        if (
            self.input == "force"
            and math.isfinite(self.rest_V_)
            and self.polarity_ != "per_recording"
        ):
            # The calibration must turn a press into a rising force.
            slope = float(np.polyval(np.polyder(self._coeffs()), self.rest_V_))
            if slope * PRESS_DIRECTION[self.polarity_] <= 0:
                raise SlipkitError(
                    f"FSRTouchSlip(input='force'): the calibration {self._coeffs().tolist()} "
                    f"has dF/dV = {slope:.4g} N/V at the rest voltage {self.rest_V_:.4g} V, "
                    f"so a press (voltage {self.polarity_}) would read as a falling force; "
                    "give the calibration of this wiring"
                )

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FSRTouchSlip:
        """Learn the polarity (``polarity="auto"``), then choose ``threshold_``.

        See :meth:`StreamDetector.fit <slipkit.baselines.base.StreamDetector.fit>`.
        Raises :class:`~slipkit.errors.SlipkitError` when ``polarity="auto"`` and no
        training recording is ever pressed; warns (:class:`PolarityWarning`) and uses
        ``"per_recording"`` when the recordings disagree.
        """
        self._validate_params()
        Xv = self._check_X(X, reset=True)
        for name in ("polarity_", "polarity_votes_", "rest_V_"):
            self.__dict__.pop(name, None)
        self._learn_polarity(Xv[:, 0], segments)
        super().fit(Xv, y, segments=segments)
        return self

    def _calibrate(
        self,
        X: FloatArray,
        y: Any,
        scores: FloatArray,
        segments: ArrayLike | None,
    ) -> None:
        self.delta_ = self._delta
        super()._calibrate(X, y, scores, segments)
        # A ROC (the sample ROC here, or the event ROC of slipkit train, which passes
        # its choice as ``threshold``) puts alpha on a training score. Scores of a
        # quantised signal (an ADC) repeat exactly across recordings, so held-out
        # scores land on alpha itself and the decision hangs on the last bit, which
        # the deployed float32 graph cannot reproduce: alpha on a training score moves
        # halfway down to the next lower one (no training decision changes).
        t = float(self.threshold_)
        finite = scores[np.isfinite(scores)]
        below = finite[finite < t]
        if below.size and np.any(finite == t):
            self.threshold_ = 0.5 * (t + float(below.max()))

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
            if self.input != "force" and self._polarity == "per_recording":
                # the first block further than delta from rest sets the press direction
                with np.errstate(invalid="ignore"):
                    away = np.abs(m - rest) > self._delta
                if not away.any():
                    return deriv, press
                k = int(np.argmax(away))
                sign = -1.0 if m[k] - rest > 0 else 1.0  # slip opposes the press
                dm = m[k:] - means[first - 1 + k : -1]
                deriv[first + k :] = sign * dm * self._per_s
                press[first + k :] = sign * (rest - m[k:])
                return deriv, press
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

    def _confirmed(self, d: FloatArray) -> FloatArray:
        """Per block: the ``confirm_events``-th largest peak of ``d`` (the paper's
        block scores, ``-inf`` where none) among the peaks known at that block
        (the streaming form computes the same numbers incrementally)."""
        nb, r, wb, k = (
            len(d),
            self._peak_gap,
            self._confirm_blocks,
            int(self.confirm_events),
        )
        out = np.full(nb, -np.inf)
        if nb <= r:
            return out
        pad = np.concatenate([np.full(r, -np.inf), d])
        left = sliding_window_view(pad, r)[: nb - r].max(axis=1)  # d[b-r .. b-1]
        right = sliding_window_view(d[1:], r).max(axis=1)  # d[b+1 .. b+r]
        mid = d[: nb - r]
        tie = self._peak_tie  # a near-equal neighbour is a tie: the graph's float32
        peak = np.isfinite(mid) & (mid > left + tie) & (mid >= right - tie)
        pv = np.where(peak, mid, -np.inf)  # peak of block b, known at block b + r
        win = sliding_window_view(np.concatenate([np.full(wb - 1, -np.inf), pv]), wb)
        out[r:] = np.partition(win, wb - k, axis=1)[:, wb - k]
        return out

    def _scores(self, X: FloatArray) -> FloatArray:
        deriv, press = self._block_stats(self._signal(X[:, 0]))
        with np.errstate(invalid="ignore"):
            ok = (press > self._delta) & np.isfinite(deriv)
        per_block = np.where(ok, deriv, -np.inf)
        if int(self.confirm_events) > 1:
            per_block = self._confirmed(per_block)
        return self._per_sample(per_block, len(X), -np.inf)

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
        self._need = int(detector.confirm_events)
        self._gap = detector._peak_gap
        self._tie = detector._peak_tie
        self._wb = detector._confirm_blocks
        self._force = detector.input == "force"
        self._coeffs = detector._coeffs() if self._force else None
        self._per_recording = not self._force and detector._polarity == "per_recording"
        self._fixed_sign = 0.0 if self._per_recording else detector._sign
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
        self._sign = self._fixed_sign  # 0: not known yet (per_recording)
        # confirmation: the last 2 gap + 1 block scores (oldest first) and the peaks
        # (block, score) inside the window
        self._block_i = -1
        self._recent: deque[float] = deque(
            [-math.inf] * (2 * self._gap + 1), maxlen=2 * self._gap + 1
        )
        self._peaks: deque[tuple[int, float]] = deque()

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
                if self._sign == 0.0 and abs(mean - rest) > self._delta:
                    self._sign = -1.0 if mean - rest > 0 else 1.0  # first press
                deriv = self._sign * (mean - self._prev) * self._per_s
                self.touched = bool(self._sign * (rest - mean) > self._delta)
                ok = self.touched and math.isfinite(deriv)
                block_score = deriv if ok else -np.inf
            else:
                block_score = -np.inf
            self._block_i += 1
            if self._need > 1:
                self._score = self._confirm(block_score)
            elif self._i // self._block >= self._first:
                self._score = block_score
            self._prev = mean
            self._acc, self._k = 0.0, 0
        self._i += 1
        return self._score, self._score >= self._threshold

    def _confirm(self, block_score: float) -> float:
        """Push one block score; return the confirmed score at this block."""
        c, r = self._block_i, self._gap
        self._recent.append(block_score)
        if c >= r:  # the block r back is now a peak or not
            vals = list(self._recent)
            mid = vals[r]
            if (
                math.isfinite(mid)
                and mid > max(vals[:r]) + self._tie
                and mid >= max(vals[r + 1 :]) - self._tie
            ):
                self._peaks.append((c - r, mid))
        while self._peaks and self._peaks[0][0] <= c - r - self._wb:
            self._peaks.popleft()
        if c < r or len(self._peaks) < self._need:
            return -math.inf
        return sorted(v for _, v in self._peaks)[-self._need]


__all__ = [
    "DEFAULT_DELTA",
    "PEAK_TIE",
    "PRESS_DIRECTION",
    "FSRStream",
    "FSRTouchSlip",
    "PolarityWarning",
]
