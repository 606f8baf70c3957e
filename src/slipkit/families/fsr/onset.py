"""FSR slip onset in 2 ms: a stick-slip release told from a knock by its shape.

A slipkit addition beside the paper's detector (:mod:`slipkit.families.fsr.touch_slip`), built
for delay. The paper's rule fires on any steep release, so a sharp external knock
(+-15-50 % of the grip, 1-5 ms edges) fires it as often as a slip does; the confirmed
variant (three peaks within 0.4 s) waits for a train of stick-slip events and is late.
What separates the two in the first milliseconds is the shape of the release:

* a **stick-slip release** lets the contact go at once (within a sample or two) and
  ends sharply, and the fingertip rings: the level stops rising where the release
  ends and within ``rebound_s`` (2 ms) has fallen back by a fraction of it;
* a **knock** is pushed through the hand: its edge is smooth (it was already rising
  before, or its last samples add little as it flattens into its plateau) and the
  level then holds for the knock's duration (5-50 ms), so nothing falls back within
  2 ms; a knock that presses first and then lets go returns to the level it came
  from and holds there.

Both detectors here read the signed signal ``s = sign (v - v_rest)`` (slip positive:
``sign`` +1 for the paper's falling wiring, -1 for a rising one), ``v_rest`` the mean
of the recording's first ``rest_samples`` samples and the sign fitted or latched at the
recording's first sample further than ``delta`` from rest, as
:class:`~slipkit.families.fsr.touch_slip.FSRTouchSlip` with one-sample blocks; deployed, the
runtime op ``press_sign`` makes ``s`` on the gripper PC (``block`` 1). Per sample ``n``
the candidate release ends ``m = round(rebound_s rate_hz)`` samples back, at
``k = n - m``, and spans ``e = round(edge_s rate_hz)`` samples:

* ``E = s[k] - s[k-e]`` (the release, V);
* ``last = s[k] - s[k-1]`` (its last sample's share);
* ``R = s[k] - s[n]`` (how far the level has fallen back by now);
* ``up = max(s[k+1..n]) - s[k]`` (how far it rose further after the release);
* ``lead = max(s[i+1] - s[i])`` over the ``q = round(lead_s rate_hz)`` steps before
  the release (how fast it was already rising);
* touched: ``-s[n] >= delta`` (the FSR is pressed at least ``delta`` now).

:class:`FSROnset` (analytic) scores ``E`` (V) where ``last >= last_frac E``,
``R >= rebound_frac E``, ``up <= rise_frac E``, ``lead <= lead_frac E``, ``E > 0``
and the FSR is touched, else ``-inf``; slip when the score reaches ``threshold_``. It
decides ``rebound_s`` after the release ends. :class:`FSROnsetLogistic` (learned) puts
the same window's features, ``R / E``, ``up / E``, ``lead / E``, ``last / E`` (each
clipped to +-2) and ``min(ln(E / size_V), 0)`` (small releases count against, large
ones do not count for), into a logistic regression trained for early decisions: the
positive samples are the first decisions on each labelled slip event (its release
ending within ``onset_label_s`` of the event's onset), the rest of every event is left
out, every other candidate (``E >= min_step_V``, touched) is negative (training data
without such a release, no knocks: every other touched release); its score is the logit
on candidates, ``-inf`` elsewhere.

Both choose a free threshold for early, correct decisions (``calibration="onset"``,
:meth:`FSROnset.onset_units`). The shapes they assume, and where they fail, are in
``docs/families/fsr.md`` ("Onset detectors").
"""

from __future__ import annotations

import math
import warnings
from collections import deque
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
from slipkit.baselines.generic import OnsetCalibration
from slipkit.errors import SlipkitError
from slipkit.families.fsr.touch_slip import (
    DEFAULT_DELTA,
    PRESS_DIRECTION,
    FSRTouchSlip,
    _sequential_sum,
)

#: The learned detector's shape features are clipped to +-FEATURE_CLIP releases (a
#: tiny release would otherwise make them unbounded).
FEATURE_CLIP = 2.0
#: The smallest release that is one (V): 1 nV, far below any ADC step, so that a flat
#: signal (every difference 0) is no release.
MIN_RELEASE_V = 1e-9
#: The learned detector's features, in order.
FEATURES = ("fall_back/E", "rise_after/E", "rise_before/E", "last/E", "size")


def _runs(flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """(start, stop) of every run of True."""
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1).tolist()
    stops = np.flatnonzero(edges == -1).tolist()
    return list(zip(starts, stops, strict=True))


def onset_matrix(lead: int, edge: int, rebound: int) -> NDArray[np.float64]:
    """``(W, K)`` matrix whose columns, applied to a window ``s`` of ``W = lead + edge
    + 1 + rebound`` samples (oldest first), give every difference the detectors read.

    The release ends at ``k = lead + edge``, the decision is at ``n = W - 1``. Columns
    (each ``s[i] - s[j]`` with two non-zero entries +-1, so any summation order gives
    the exact difference): ``E = s[k] - s[k-edge]``, ``last = s[k] - s[k-1]``,
    ``R = s[k] - s[n]``, ``s[k] - s[k+j]`` for ``j = 1..rebound`` (minus each rise
    after the release), ``s[i] - s[i+1]`` for the ``lead`` steps before it (minus each
    rise), and ``-s[n]`` (the press, one entry).
    """
    w = lead + edge + 1 + rebound
    k, n = lead + edge, w - 1
    cols = []

    def diff(i: int, j: int) -> NDArray[np.float64]:
        c = np.zeros(w)
        c[i] += 1.0
        c[j] -= 1.0
        return c

    cols.append(diff(k, k - edge))
    cols.append(diff(k, k - 1))
    cols.append(diff(k, n))
    cols.extend(diff(k, k + j) for j in range(1, rebound + 1))
    cols.extend(diff(i, i + 1) for i in range(k - edge - lead, k - edge))
    press = np.zeros(w)
    press[n] = -1.0
    cols.append(press)
    return np.column_stack(cols)


class FSROnset(OnsetCalibration, StreamDetector):
    """Analytic FSR slip onset: a one-sample release that rings back (module docstring).

    Parameters
    ----------
    rate_hz : float
        Sample rate (Hz); the paper: 2 kHz.
    rest_samples : int
        Samples at the start of each recording averaged into ``v_rest`` (the paper's 10).
    delta : float or None
        Touch threshold: the FSR is touched where ``sign (v_rest - v) >= delta`` (V);
        None: 0.2 V (:data:`~slipkit.families.fsr.touch_slip.DEFAULT_DELTA`).
    polarity : {"auto", "falling", "rising", "per_recording"}
        The wiring, as :class:`~slipkit.families.fsr.touch_slip.FSRTouchSlip`'s (``"auto"``:
        learned by ``fit``; training recordings of both wirings give
        ``"per_recording"``: each recording's first sample further than ``delta``
        from rest sets its sign).
    edge_s : float
        The release is the rise over this long (s; at least one sample).
    last_frac : float
        The release's last sample must carry at least this fraction of it.
    rebound_s : float
        How long after the release the detector looks for the fall back (s); it
        decides this long after the release ends.
    rebound_frac : float
        The level must have fallen back by at least this fraction of the release.
    rise_frac : float
        After the release no sample may rise above it by more than this fraction of it.
    lead_s : float
        How long before the release the detector checks that the level was not
        already rising (s); 0: no check.
    lead_frac : float
        No step in ``lead_s`` before the release may rise by more than this fraction
        of it.
    calibration : {"onset", "sample"}
        How ``fit`` chooses a free threshold
        (:class:`~slipkit.baselines.generic.OnsetCalibration`, with the units of
        :meth:`onset_units`): ``"onset"`` for early, correct decisions -- every
        training slip event's largest score in its first ``edge_s + rebound_s`` + 1 ms
        against every recording's largest score outside its events, best Youden point,
        mid-gap (when nothing outside the events scores: half the weakest slip's
        score); ``"sample"``: the per-sample ROC.
    threshold : float or None
        The smallest release ``E`` (V) that is slip; None: chosen by ``calibration``.
    roc_point : {"youden", "closest"}
        ROC point of the per-sample ROC.

    Attributes
    ----------
    polarity_, polarity_votes_, rest_V_
        As :class:`~slipkit.families.fsr.touch_slip.FSRTouchSlip`'s.
    delta_ : float
        The touch threshold used (V).
    threshold_, classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "rest_samples": [Interval(Integral, 1, None, closed="left")],
        "delta": [Interval(Real, 0, None, closed="neither"), None],
        "polarity": [StrOptions({"auto", "falling", "rising", "per_recording"})],
        "edge_s": [Interval(Real, 0, None, closed="left")],
        "last_frac": [Interval(Real, 0, None, closed="left")],
        "rebound_s": [Interval(Real, 0, None, closed="neither")],
        "rebound_frac": [Interval(Real, 0, None, closed="left")],
        "rise_frac": [Interval(Real, 0, None, closed="left")],
        "lead_s": [Interval(Real, 0, None, closed="left")],
        "lead_frac": [Interval(Real, 0, None, closed="left")],
        "calibration": [StrOptions({"onset", "sample"})],
    }
    n_channels: ClassVar[int | None] = 1

    def __init__(
        self,
        *,
        rate_hz: float = 2000.0,
        rest_samples: int = 10,
        delta: float | None = None,
        polarity: str = "auto",
        edge_s: float = 0.0005,
        last_frac: float = 0.2,
        rebound_s: float = 0.002,
        rebound_frac: float = 0.3,
        rise_frac: float = 0.2,
        lead_s: float = 0.001,
        lead_frac: float = 0.5,
        calibration: str = "onset",
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.calibration = calibration
        self.rate_hz = rate_hz
        self.rest_samples = rest_samples
        self.delta = delta
        self.polarity = polarity
        self.edge_s = edge_s
        self.last_frac = last_frac
        self.rebound_s = rebound_s
        self.rebound_frac = rebound_frac
        self.rise_frac = rise_frac
        self.lead_s = lead_s
        self.lead_frac = lead_frac

    # -- settings ------------------------------------------------------------------
    @property
    def edge_samples(self) -> int:
        """Samples the release spans (at least 1)."""
        return max(1, round(float(self.edge_s) * float(self.rate_hz)))

    @property
    def rebound_samples(self) -> int:
        """Samples from the release's end to the decision (at least 1)."""
        return max(1, round(float(self.rebound_s) * float(self.rate_hz)))

    @property
    def onset_frames(self) -> int:  # type: ignore[override]
        """Samples from a slip onset that count as on time in the ``"onset"``
        calibration: the release and its decision (``edge_s + rebound_s``) plus 1 ms."""
        ms = max(1, round(0.001 * float(self.rate_hz)))
        return self.edge_samples + self.rebound_samples + ms

    @property
    def lead_samples(self) -> int:
        """Steps before the release that are checked (0: none)."""
        return max(0, round(float(self.lead_s) * float(self.rate_hz)))

    @property
    def window_samples(self) -> int:
        """Samples one decision reads."""
        return self.lead_samples + self.edge_samples + 1 + self.rebound_samples

    def matrix(self) -> NDArray[np.float64]:
        """:func:`onset_matrix` of this detector's window."""
        return onset_matrix(self.lead_samples, self.edge_samples, self.rebound_samples)

    @property
    def _delta(self) -> float:
        return float(DEFAULT_DELTA["voltage"] if self.delta is None else self.delta)

    @property
    def _polarity(self) -> str:
        known = getattr(self, "polarity_", None)
        if known is not None:
            return str(known)
        if self.polarity == "auto":
            raise SlipkitError(
                f"{type(self).__name__}: polarity 'auto' is learned by fit from "
                "recordings that include a press; call fit, or set polarity to "
                "'falling' (voltage falls with force, the paper) or 'rising'"
            )
        return str(self.polarity)

    @property
    def fixed_sign(self) -> float:
        """The slip sign of the voltage (+1: it rises on a release), 0 for ``per_recording``."""
        polarity = self._polarity
        return 0.0 if polarity == "per_recording" else -PRESS_DIRECTION[polarity]

    def _conditions(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per column of :func:`onset_matrix`: (coefficient of ``E``, constant) such
        that the sample passes where every ``column - (coef E + const) >= 0``."""
        q, m = self.lead_samples, self.rebound_samples
        coef = np.concatenate(
            [
                [0.0, float(self.last_frac), float(self.rebound_frac)],
                np.full(m, -float(self.rise_frac)),
                np.full(q, -float(self.lead_frac)),
                [0.0],
            ]
        )
        const = np.zeros(len(coef))
        const[0] = MIN_RELEASE_V
        const[-1] = self._delta
        return coef, const

    # -- fit -------------------------------------------------------------------------
    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FSROnset:
        """Learn the polarity (``polarity="auto"``), then choose ``threshold_``.

        See :meth:`StreamDetector.fit <slipkit.baselines.base.StreamDetector.fit>`;
        the polarity rules (and their refusals) are
        :class:`~slipkit.families.fsr.touch_slip.FSRTouchSlip`'s.
        """
        self._validate_params()
        Xv = self._check_X(X, reset=True)
        self._learn_polarity(Xv[:, 0], segments)
        self.delta_ = self._delta
        self._fit_model(Xv, np.asarray(y), segments)
        super().fit(Xv, y, segments=segments)
        return self

    def _fit_model(
        self, X: FloatArray, y: NDArray[Any], segments: ArrayLike | None
    ) -> None:
        """Learned detectors fit their model here (after the polarity, before the threshold)."""

    def _calibrate(
        self,
        X: FloatArray,
        y: NDArray[np.int_],
        scores: FloatArray,
        segments: ArrayLike | None,
    ) -> None:
        super()._calibrate(X, y, scores, segments)
        if self.threshold is not None or self.calibration != "onset":
            return
        units, best = self.onset_units(y, scores, segments)
        pos = best[(units == 1) & np.isfinite(best)]
        if not len(pos) or np.isfinite(best[units == 0]).any() or pos.min() <= 0:
            return
        # Nothing outside the slips scores (clean training data): the mid-gap rule
        # would sit on the weakest training slip, and a slightly weaker one would be
        # missed; the gap is from 0 (no release; a logit of 0, p = 0.5) to it.
        self.threshold_ = 0.5 * float(pos.min())
        finite = np.where(np.isfinite(scores), scores, np.finfo(np.float64).min)
        pred = finite >= self.threshold_
        self.tpr_ = float(pred[y == 1].mean()) if (y == 1).any() else float("nan")
        self.fnr_ = 1.0 - self.tpr_
        self.fpr_ = float(pred[y == 0].mean()) if (y == 0).any() else float("nan")
        self.tnr_ = 1.0 - self.fpr_

    def onset_units(
        self, y: NDArray[np.int_], scores: FloatArray, segments: ArrayLike | None
    ) -> tuple[NDArray[np.int_], FloatArray]:
        """Units of the ``"onset"`` calibration: (label, largest score).

        Every labelled slip event (a run of slip samples) is a positive unit, its
        largest score in its first :attr:`onset_frames` samples (its first decision:
        on time); every recording's time outside its events (and their first
        :attr:`onset_frames` samples) is one negative unit, its largest score there.
        """
        labels: list[int] = []
        best: list[float] = []
        k = int(self.onset_frames)
        for a, b in segment_bounds(len(y), segments):
            outside = np.ones(b - a, dtype=bool)
            for r0, r1 in _runs(y[a:b] == 1):
                labels.append(1)
                best.append(float(np.max(scores[a + r0 : a + min(b - a, r0 + k)])))
                outside[r0 : max(r1, min(b - a, r0 + k))] = False
            if outside.any():
                labels.append(0)
                best.append(float(np.max(scores[a:b][outside])))
        return np.asarray(labels, dtype=int), np.asarray(best)

    def _learn_polarity(self, v: FloatArray, segments: ArrayLike | None) -> None:
        # FSRTouchSlip's rules with one-sample blocks (its refusals name this class)
        probe = FSRTouchSlip(
            input="voltage",
            rate_hz=self.rate_hz,
            block=1,
            rest_samples=self.rest_samples,
            delta=self.delta,
            polarity=self.polarity,
        )
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                probe._learn_polarity(v, segments)
        except SlipkitError as err:
            raise SlipkitError(
                str(err).replace("FSRTouchSlip", type(self).__name__)
            ) from None
        for w in caught:
            warnings.warn(
                str(w.message).replace("FSRTouchSlip", type(self).__name__),
                w.category,
                stacklevel=3,
            )
        self.polarity_ = probe.polarity_
        self.polarity_votes_ = probe.polarity_votes_
        self.rest_V_ = probe.rest_V_

    # -- batch -----------------------------------------------------------------------
    def signed(self, v: FloatArray) -> tuple[FloatArray, int]:
        """The signed signal ``sign (v - v_rest)`` of ONE recording and its first
        decided sample (``len(v)`` when it never decides: no press for
        ``per_recording``). What the runtime op ``press_sign`` feeds the graph."""
        n, rest_n = len(v), int(self.rest_samples)
        head = v[:rest_n]
        finite = head[np.isfinite(head)].tolist()
        rest = _sequential_sum(finite) / len(finite) if finite else math.nan
        first = max(self.window_samples - 1, rest_n - 1)
        sign = self.fixed_sign
        if sign == 0.0:  # the first sample after the rest further than delta
            with np.errstate(invalid="ignore"):
                away = np.abs(v[rest_n:] - rest) > self._delta
            if not away.any():
                return np.zeros(n), n
            at = rest_n + int(np.argmax(away))
            sign = -1.0 if v[at] - rest > 0 else 1.0
            first = max(first, at)
        s = v - rest
        if sign < 0:
            s = -s
        return s, first

    def columns(self, s: FloatArray) -> FloatArray:
        """:func:`onset_matrix` columns of every window of ``s``; row ``i`` ends at
        sample ``i + W - 1``."""
        w = self.window_samples
        if len(s) < w:
            return np.empty((0, w))
        windows = sliding_window_view(s, w)
        return np.asarray(windows @ self.matrix())

    def _window_scores(self, cols: FloatArray) -> FloatArray:
        coef, const = self._conditions()
        release = cols[:, :1]
        with np.errstate(invalid="ignore"):
            ok = np.min(cols - (release * coef + const), axis=1) >= 0
        return np.where(ok, cols[:, 0], -np.inf)

    def _scores(self, X: FloatArray) -> FloatArray:
        s, first = self.signed(X[:, 0])
        out = np.full(len(s), -np.inf)
        w = self.window_samples
        if len(s) < w or first >= len(s):
            return out
        out[w - 1 :] = self._window_scores(self.columns(s))
        out[:first] = -np.inf
        return out

    # -- streaming ---------------------------------------------------------------------
    def _new_stream(self) -> OnsetStream:
        return OnsetStream(self)


class FSROnsetLogistic(FSROnset):
    """Learned FSR slip onset: logistic regression on the onset window's shape (module docstring).

    Parameters
    ----------
    rate_hz, rest_samples, delta, polarity, edge_s, rebound_s, lead_s
        As :class:`FSROnset` (the window and the signed signal).
    min_step_V : float
        Candidates: releases ``E`` of at least this (V), touched; every other sample
        scores ``-inf``.
    size_V : float
        The size feature is ``min(ln(E / size_V), 0)``.
    onset_label_s : float
        Positive training samples: candidates whose release ends within this long (s)
        after a labelled slip onset (the first decisions on the event).
    C : float
        Inverse L2 strength of the logistic regression (balanced class weights).
    calibration : {"onset", "sample"}
        As :class:`FSROnset`.
    threshold : float or None
        Slip where the logit reaches it; None: chosen by ``calibration``.
    roc_point : {"youden", "closest"}
        ROC point of the per-sample ROC.

    Attributes
    ----------
    coef_ : ndarray (5,)
        Weights of :data:`FEATURES` (the standardisation folded in).
    intercept_ : float
        The logit's constant.
    n_train_ : dict
        Training candidates: ``{"positive": n, "negative": n}``.
    polarity_, polarity_votes_, rest_V_, delta_, threshold_, classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        As :class:`FSROnset`.
    """

    #: shown as a learned estimator in comparisons (it fits a logistic regression)
    slipkit_kind = "learned"

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **{
            k: v
            for k, v in FSROnset._parameter_constraints.items()
            if k not in ("last_frac", "rebound_frac", "rise_frac", "lead_frac")
        },
        "min_step_V": [Interval(Real, 0, None, closed="neither")],
        "size_V": [Interval(Real, 0, None, closed="neither")],
        "onset_label_s": [Interval(Real, 0, None, closed="left")],
        "C": [Interval(Real, 0, None, closed="neither")],
    }

    def __init__(
        self,
        *,
        rate_hz: float = 2000.0,
        rest_samples: int = 10,
        delta: float | None = None,
        polarity: str = "auto",
        edge_s: float = 0.0005,
        rebound_s: float = 0.002,
        lead_s: float = 0.001,
        min_step_V: float = 0.02,
        size_V: float = 0.08,
        onset_label_s: float = 0.001,
        C: float = 1.0,
        calibration: str = "onset",
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(
            rate_hz=rate_hz,
            rest_samples=rest_samples,
            delta=delta,
            polarity=polarity,
            edge_s=edge_s,
            rebound_s=rebound_s,
            lead_s=lead_s,
            calibration=calibration,
            threshold=threshold,
            roc_point=roc_point,
        )
        self.min_step_V = min_step_V
        self.size_V = size_V
        self.onset_label_s = onset_label_s
        self.C = C

    def features(self, cols: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """:data:`FEATURES` of every window (rows of :meth:`columns`) and whether it
        is a candidate."""
        q, m = self.lead_samples, self.rebound_samples
        release = cols[:, 0]
        with np.errstate(invalid="ignore", divide="ignore"):
            cand = (release - float(self.min_step_V) >= 0) & (
                cols[:, -1] - self._delta >= 0
            )
            # the columns hold minus the rises: up and lead are their negated minima
            up = -np.min(cols[:, 3 : 3 + m], axis=1)
            lead = -np.min(cols[:, 3 + m : 3 + m + q], axis=1) if q else 0.0 * release
            shape = np.column_stack([cols[:, 2], up, lead, cols[:, 1]])
            feats = np.column_stack(
                [
                    np.clip(shape / release[:, None], -FEATURE_CLIP, FEATURE_CLIP),
                    np.minimum(np.log(release / float(self.size_V)), 0.0),
                ]
            )
        return feats, cand

    def _fit_model(
        self, X: FloatArray, y: NDArray[Any], segments: ArrayLike | None
    ) -> None:
        yv = y.astype(int).reshape(-1)
        w = self.window_samples
        lag = self.rebound_samples  # from the release's end to its decision
        label_n = round(float(self.onset_label_s) * float(self.rate_hz))
        parts, labels, small = [], [], []
        for a, b in segment_bounds(len(X), segments):
            s, first = self.signed(X[a:b, 0])
            if b - a < w or first >= b - a:
                continue
            cols = self.columns(s)
            feats, cand = self.features(cols)
            ends = np.arange(w - 1, b - a)
            ok = (ends >= first) & np.isfinite(feats).all(axis=1)
            # any touched release, for data whose only large releases are slips
            weak = ok & (cols[:, -1] - self._delta >= 0) & (cols[:, 0] > MIN_RELEASE_V)
            cand &= ok
            label = np.zeros(b - a, dtype=int)
            used = np.ones(b - a, dtype=bool)
            for r0, r1 in _runs(yv[a:b] > 0):
                # decisions whose window reads the event: the first ones positive,
                # the rest left out
                used[r0 : min(b - a, r1 + w)] = False
                lo, hi = r0 + lag, min(b - a - 1, r0 + lag + label_n)
                label[lo : hi + 1] = 1
                used[lo : hi + 1] = True
            keep = cand & used[ends]
            parts.append(feats[keep])
            labels.append(label[ends][keep])
            small.append(feats[weak & ~cand & used[ends] & (label[ends] == 0)])
        F = np.vstack(parts) if parts else np.empty((0, len(FEATURES)))
        L = np.concatenate(labels) if labels else np.empty(0, dtype=int)
        if not np.any(L == 0) and small:
            # no other release of min_step_V (no knocks in the training data): every
            # other touched release is a negative
            weak_f = np.vstack(small)
            F = np.vstack([F, weak_f])
            L = np.concatenate([L, np.zeros(len(weak_f), dtype=int)])
        if len(np.unique(L)) < 2:
            raise SlipkitError(
                f"{type(self).__name__}: the training recordings give "
                f"{int(np.sum(L == 1))} slip-onset and {int(np.sum(L == 0))} other "
                f"touched releases (candidates >= {self.min_step_V:g} V, else any); "
                "both are needed (recordings with labelled slip events and pressed time)"
            )
        scaler = StandardScaler().fit(F)
        clf = LogisticRegression(
            C=float(self.C), class_weight="balanced", max_iter=2000
        ).fit(scaler.transform(F), L)
        w_std = clf.coef_[0] / scaler.scale_
        self.coef_ = np.asarray(w_std, dtype=np.float64)
        self.intercept_ = float(clf.intercept_[0] - np.dot(scaler.mean_, w_std))
        self.n_train_ = {
            "positive": int(np.sum(L == 1)),
            "negative": int(np.sum(L == 0)),
        }

    def _window_scores(self, cols: FloatArray) -> FloatArray:
        check_is_fitted(self, "coef_")
        feats, cand = self.features(cols)
        logit = feats @ self.coef_ + self.intercept_
        with np.errstate(invalid="ignore"):
            ok = cand & np.isfinite(logit)
        return np.where(ok, logit, -np.inf)


class OnsetStream:
    """Sample-by-sample :class:`FSROnset` / :class:`FSROnsetLogistic` (the last
    window of samples, the rest level and the sign)."""

    def __init__(self, detector: FSROnset) -> None:
        self._det = detector
        self._w = detector.window_samples
        self._rest_n = int(detector.rest_samples)
        self._delta = detector._delta
        self._fixed = detector.fixed_sign
        self._threshold = float(detector.threshold_)
        self.reset()

    def reset(self) -> None:
        """Forget the recording (rest level, sign, window)."""
        self._i = 0
        self._head: list[float] = []
        self._rest = math.nan
        self._sign = self._fixed
        self._ring: deque[float] = deque(maxlen=self._w)

    def update(self, sample: ArrayLike) -> tuple[float, bool]:
        """Feed one voltage sample (V); return (score, slip)."""
        v = float(np.asarray(sample, dtype=np.float64).reshape(-1)[0])
        self._ring.append(v)
        i = self._i
        self._i += 1
        if i < self._rest_n:
            self._head.append(v)
            if i == self._rest_n - 1:
                finite = [x for x in self._head if math.isfinite(x)]
                self._rest = (
                    _sequential_sum(finite) / len(finite) if finite else math.nan
                )
        if (
            self._sign == 0.0
            and i >= self._rest_n
            and abs(v - self._rest) > self._delta
        ):
            self._sign = -1.0 if v - self._rest > 0 else 1.0
        if i < self._w - 1 or i < self._rest_n - 1 or self._sign == 0.0:
            return -math.inf, False
        s = np.asarray(self._ring, dtype=np.float64) - self._rest
        if self._sign < 0:
            s = -s
        score = float(self._det._window_scores(self._det.columns(s))[-1])
        return score, score >= self._threshold


def slip_sign_step(detector: FSROnset) -> dict[str, Any]:
    """The runtime step (``press_sign``, one-sample blocks) that makes the signed
    signal from a stream: its rest level, and its sign fixed or latched at its first
    sample further than ``delta`` from rest, as :meth:`FSROnset.signed`."""
    check_is_fitted(detector, "threshold_")
    step: dict[str, Any] = {
        "op": "press_sign",
        "rest_frames": int(detector.rest_samples),
        "block": 1,
        "hop": 1,
        "delta": float(detector.delta_),
    }
    sign = detector.fixed_sign
    if sign != 0.0:
        step["sign"] = int(sign)
    return step


__all__ = [
    "FEATURES",
    "FEATURE_CLIP",
    "MIN_RELEASE_V",
    "FSROnset",
    "FSROnsetLogistic",
    "OnsetStream",
    "onset_matrix",
    "slip_sign_step",
]
