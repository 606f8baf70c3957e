"""Trial events: what a debounced detector does to each grasp, its cost, and the operating point.

A detector decides per sample (``score >= threshold``); the gripper reacts to *alarms*:
an alarm is declared at the ``debounce_k``-th consecutive sample at or above the
threshold, and a new alarm needs that run to end first. Per trial, given the sample
times, the scores, whether the trial slipped (``True`` / ``False`` / ``None`` =
unknown) and its onset (s; NaN = unknown), :func:`trial_events` gives

* ``detected`` -- a slip trial with an alarm at or after the onset (unknown onset: any
  alarm); None for a trial without (known) slip;
* ``early_alarm`` -- an alarm before the onset (a trial without slip: any alarm); None
  when the onset or the outcome is unknown;
* ``delay_ms`` -- first alarm at or after the onset minus the onset;
* ``false_alarms`` and ``nonslip_s`` -- alarms declared in non-slip time and the
  length of that time (the per-sample slip truth when given, else the time before the
  onset; a whole trial without slip);
* ``disturbances`` / ``disturbances_fired`` -- disturbance intervals (s) and those with
  an alarm declared inside them (plus a tolerance).

The cost of one trial (:class:`Cost`, lower is better) is ``miss`` for a slip not
detected, plus ``early_alarm`` for an early alarm, plus ``min(delay_ms x delay_ms
weight, miss)`` for a detection (a detection later than ``miss / weight`` ms costs as
much as a miss). A trial of unknown onset is scored on detected / not detected only.
:func:`summarise` turns the trials into the columns every detection comparison
reports; :func:`choose_operating_point` picks (threshold, debounce) with the lowest
mean cost on validation trials among the points within the :class:`Limits`.

numpy + pandas only; the grid search is hand-written because the cost is a trial-level,
debounced quantity that scikit-learn's threshold tuners (per-sample scorers) cannot
express.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from slipkit.errors import SlipkitError

FloatArray = NDArray[np.float64]

#: label naming whether a trial slipped: 1, 0 (NaN: unknown); separate from its onset
SLIPPED_LABEL = "slipped"


@dataclass(frozen=True)
class Cost:
    """What one test trial costs a grasp (weights; lower total is better).

    Attributes
    ----------
    miss : float
        A slip trial without an alarm at or after its onset.
    early_alarm : float
        An alarm before the onset (a trial without slip: any alarm).
    delay_ms : float
        Per millisecond from the onset to the first alarm after it, capped at ``miss``.
    """

    miss: float = 1.0
    early_alarm: float = 0.2
    delay_ms: float = 0.002


@dataclass(frozen=True)
class Limits:
    """Rates a deployable operating point must not exceed (None: no limit).

    Attributes
    ----------
    max_early_alarm_rate : float or None
        Share of trials with an early alarm.
    max_alarms_per_disturbance : float or None
        Share of disturbances (bumps, knocks without slip) with an alarm.
    """

    max_early_alarm_rate: float | None = 0.25
    max_alarms_per_disturbance: float | None = None

    def excess(self, summary: Mapping[str, Any]) -> float:
        """How far the summary's rates lie over their limits, summed (0: within)."""
        total = 0.0
        for key, column in (
            ("max_early_alarm_rate", "early_alarm_rate"),
            ("max_alarms_per_disturbance", "alarms_per_disturbance"),
        ):
            limit, rate = getattr(self, key), _float(summary.get(column))
            if limit is not None and math.isfinite(rate):
                total += max(rate - limit, 0.0)
        return total

    def breach(self, summary: Mapping[str, Any]) -> str | None:
        """Why ``summary`` is over a limit (None: within every limit; a NaN rate is not held)."""
        for key, column, what in (
            ("max_early_alarm_rate", "early_alarm_rate", "early alarms"),
            ("max_alarms_per_disturbance", "alarms_per_disturbance", "disturbances"),
        ):
            limit = getattr(self, key)
            rate = _float(summary.get(column))
            if limit is not None and math.isfinite(rate) and rate > limit + 1e-12:
                return (
                    f"{what} {rate * 100:.0f} % > {limit * 100:g} %"
                    if what == "early alarms"
                    else f"fires on {rate * 100:.0f} % of disturbances > {limit * 100:g} %"
                )
        return None


#: the debounce candidates and threshold quantiles of an operating-point search
DEFAULT_DEBOUNCE = (1, 2, 3, 5)
DEFAULT_THRESHOLDS = 64


def _float(value: Any) -> float:
    try:
        return math.nan if value is None else float(value)
    except (TypeError, ValueError):
        return math.nan


def _fraction(where: str, key: str, value: Any) -> float | None:
    if value is None:
        return None
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not 0.0 <= float(value) <= 1.0
    ):
        raise SlipkitError(
            f"{where}.{key}: must be a fraction in [0, 1] (0.25 = 25 %) or null; got "
            f"{value!r}"
        )
    return float(value)


def parse_cost(node: Mapping[str, Any] | None, where: str) -> Cost:
    """A ``cost:`` mapping checked (``{miss, early_alarm, delay_ms}``, numbers >= 0).

    Raises
    ------
    SlipkitError
        Naming ``where`` and the key: not a mapping, an unknown key, a negative or
        non-numeric weight.
    """
    if node is None:
        return Cost()
    if not isinstance(node, Mapping):
        raise SlipkitError(
            f"{where}: must be a mapping such as {{miss: 1.0, early_alarm: 0.2, "
            f"delay_ms: 0.002}}; got {node!r}"
        )
    known = {f for f in Cost.__dataclass_fields__}
    out: dict[str, float] = {}
    for key, value in node.items():
        if key not in known:
            raise SlipkitError(f"{where}.{key}: unknown cost; known: {sorted(known)}")
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(float(value))
            or float(value) < 0
        ):
            raise SlipkitError(
                f"{where}.{key}: must be a number >= 0 (a weight); got {value!r}"
            )
        out[str(key)] = float(value)
    return Cost(**out)


def parse_limits(node: Mapping[str, Any], where: str) -> Limits:
    """``max_early_alarm_rate`` / ``max_alarms_per_disturbance`` of ``node`` checked
    (fractions in [0, 1] or null; an absent key keeps the :class:`Limits` default)."""
    kw: dict[str, float | None] = {}
    for key in ("max_early_alarm_rate", "max_alarms_per_disturbance"):
        if key in node:
            kw[key] = _fraction(where, key, node[key])
    return Limits(**kw)


#: the keys of a task's ``operating_point`` mapping (:func:`parse_operating_point`)
OPERATING_POINT_KEYS = (
    "debounce",
    "thresholds",
    "cost",
    "max_early_alarm_rate",
    "max_alarms_per_disturbance",
)
#: summary columns a smaller value of which is better (a cost, a delay, a rate of mistakes)
MINIMISED = frozenset(
    {
        "cost",
        "delay_ms",
        "delay_p90_ms",
        "early_alarm_rate",
        "false_alarms_per_min",
        "missed",
        "alarms_per_disturbance",
    }
)


def parse_operating_point(
    node: Mapping[str, Any] | None, where: str = "task.operating_point"
) -> dict[str, Any] | None:
    """A task's ``operating_point`` mapping checked: ``debounce`` candidates (whole
    numbers >= 1), ``thresholds`` quantiles (>= 2), the ``cost`` (:func:`parse_cost`)
    and the limits (:func:`parse_limits`); None stays None.

    Returns
    -------
    dict or None
        ``{"debounce": [int], "thresholds": int, "cost": Cost, "limits": Limits}``.

    Raises
    ------
    SlipkitError
        Naming ``where`` and the key at fault.
    """
    if node is None:
        return None
    if not isinstance(node, Mapping):
        raise SlipkitError(
            f"{where}: must be a mapping such as {{debounce: [1, 2, 3, 5], thresholds: "
            f"64}} or null; got {node!r}"
        )
    unknown = sorted(str(k) for k in node if k not in OPERATING_POINT_KEYS)
    if unknown:
        raise SlipkitError(
            f"{where}.{unknown[0]}: unknown key; known: {list(OPERATING_POINT_KEYS)}"
        )
    debounce = node.get("debounce", list(DEFAULT_DEBOUNCE))
    if (
        not isinstance(debounce, Sequence)
        or isinstance(debounce, str)
        or not debounce
        or any(isinstance(k, bool) or not isinstance(k, int) or k < 1 for k in debounce)
    ):
        raise SlipkitError(
            f"{where}.debounce: must be a non-empty list of whole numbers >= 1 "
            f"(consecutive samples); got {debounce!r}"
        )
    n = node.get("thresholds", DEFAULT_THRESHOLDS)
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise SlipkitError(
            f"{where}.thresholds: must be a whole number >= 2 (quantiles); got {n!r}"
        )
    return {
        "debounce": [int(k) for k in debounce],
        "thresholds": int(n),
        "cost": parse_cost(node.get("cost"), f"{where}.cost"),
        "limits": parse_limits(node, where),
    }


def slipped_of(labels: Mapping[str, Any], onset_s: float) -> bool | None:
    """Whether a trial slipped, from its labels: the ``slipped`` label (1 / 0; NaN:
    unknown, True when an onset is known) when the dataset has one, else a known onset
    (a dataset without the label says no slip by a NaN onset, as simulated ones do)."""
    if SLIPPED_LABEL in labels:
        value = _float(labels[SLIPPED_LABEL])
        if math.isfinite(value):
            return bool(value)
        return True if math.isfinite(onset_s) else None
    return bool(math.isfinite(onset_s))


@dataclass(frozen=True)
class TrialTruth:
    """What happened in one trial.

    Attributes
    ----------
    trial_id : str
    t : ndarray
        Sample times (s).
    slipped : bool or None
        Did it slip (None: unknown).
    onset_s : float
        Slip onset (s; NaN: unknown or none).
    slip : ndarray of bool or None
        Per-sample slip truth (None: slip from the onset on).
    disturbances : tuple of (float, float)
        Disturbance intervals (start, end), s.
    """

    trial_id: str
    t: FloatArray
    slipped: bool | None
    onset_s: float = math.nan
    slip: NDArray[np.bool_] | None = None
    disturbances: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class TrialEvents:
    """One trial's alarms against its truth (see the module doc; None: not defined)."""

    trial_id: str
    slipped: bool | None
    onset_s: float
    n_alarms: int
    first_alarm_s: float
    detected: bool | None
    early_alarm: bool | None
    delay_ms: float
    false_alarms: int
    nonslip_s: float
    disturbances: int
    disturbances_fired: int


def alarm_indices(
    scores: ArrayLike, threshold: float, debounce_k: int
) -> NDArray[np.intp]:
    """Samples where an alarm is declared: the ``debounce_k``-th consecutive sample with
    ``score >= threshold`` (once per run; NaN / -inf never reach a threshold)."""
    k = int(debounce_k)
    if k < 1:
        raise ValueError(f"debounce_k must be >= 1; got {debounce_k!r}")
    above = np.asarray(scores, dtype=np.float64) >= threshold
    idx = np.arange(len(above))
    last_reset = np.maximum.accumulate(np.where(above, -1, idx))
    run = idx - last_reset
    return np.flatnonzero(run == k)


def _dt(t: FloatArray) -> float:
    steps = np.diff(t)
    steps = steps[steps > 0]
    return float(np.median(steps)) if len(steps) else 0.0


def trial_events(
    truth: TrialTruth,
    scores: ArrayLike,
    threshold: float,
    debounce_k: int,
    *,
    tolerance_s: float = 0.0,
) -> TrialEvents:
    """The alarms of one trial's ``scores`` at (``threshold``, ``debounce_k``) against ``truth``."""
    t = np.asarray(truth.t, dtype=np.float64)
    s = np.asarray(scores, dtype=np.float64)
    if s.shape != t.shape:
        raise ValueError(f"scores {s.shape} and times {t.shape} differ in shape")
    idx = alarm_indices(s, threshold, debounce_k)
    at = t[idx]
    onset = float(truth.onset_s)
    known = math.isfinite(onset)
    slipped = truth.slipped
    detected: bool | None = None
    early: bool | None = None
    delay = math.nan
    if slipped is True:
        if known:
            after = at[at >= onset]
            detected = bool(len(after))
            early = bool((at < onset).any())
            delay = (float(after[0]) - onset) * 1000.0 if len(after) else math.nan
        else:
            detected = bool(len(at))
    elif slipped is False:
        early = bool(len(at))
    # non-slip time: the per-sample truth, else before the onset (all of a no-slip trial)
    nonslip: NDArray[np.bool_] | None
    if truth.slip is not None and slipped is not None:
        nonslip = ~np.asarray(truth.slip, dtype=bool)
    elif slipped is False:
        nonslip = np.ones(len(t), dtype=bool)
    elif slipped is True and known:
        nonslip = t < onset
    else:
        nonslip = None  # unknown: no false-alarm accounting
    false_alarms = int(nonslip[idx].sum()) if nonslip is not None else 0
    nonslip_s = float(nonslip.sum()) * _dt(t) if nonslip is not None else 0.0
    fired = sum(
        bool(((at >= a) & (at <= b + tolerance_s)).any()) for a, b in truth.disturbances
    )
    return TrialEvents(
        trial_id=str(truth.trial_id),
        slipped=slipped,
        onset_s=onset,
        n_alarms=len(idx),
        first_alarm_s=float(at[0]) if len(at) else math.nan,
        detected=detected,
        early_alarm=early,
        delay_ms=delay,
        false_alarms=false_alarms,
        nonslip_s=nonslip_s,
        disturbances=len(truth.disturbances),
        disturbances_fired=int(fired),
    )


def trial_cost(ev: TrialEvents, cost: Cost) -> float:
    """One trial's cost (NaN when its outcome is unknown: it is left out of the mean)."""
    if ev.slipped is None:
        return math.nan
    total = 0.0
    if ev.slipped and ev.detected is False:
        total += cost.miss
    if ev.early_alarm:
        total += cost.early_alarm
    if ev.detected and math.isfinite(ev.delay_ms):
        total += min(max(ev.delay_ms, 0.0) * cost.delay_ms, cost.miss)
    return total


#: the summary columns of :func:`summarise`, in table order
SUMMARY_COLUMNS = (
    "detected_rate",
    "early_alarm_rate",
    "false_alarms_per_min",
    "alarms_per_disturbance",
    "delay_ms",
    "delay_p90_ms",
    "n_slips",
    "missed",
    "event_trials",
    "unknown_onset_trials",
    "disturbances",
    "cost",
    "cost_without_detector",
)


def summarise(events: Sequence[TrialEvents], cost: Cost) -> dict[str, Any]:
    """The detection columns over trials.

    ``detected_rate`` (slips detected / slip trials), ``early_alarm_rate`` (trials with
    an early alarm / trials where it is defined), ``false_alarms_per_min`` (alarms in
    non-slip time per minute of it), ``alarms_per_disturbance`` (share of disturbances
    with an alarm; NaN without disturbances), ``delay_ms`` (median) and
    ``delay_p90_ms``, ``n_slips``, ``missed``, ``event_trials`` (trials of known
    outcome), ``unknown_onset_trials`` (slip trials scored on detection only),
    ``disturbances``, ``cost`` (mean over trials of known outcome),
    ``cost_without_detector`` (what never alarming costs on the same trials: every slip
    missed; a detector is worth deploying only below it) and
    ``trial_balanced_accuracy`` (the mean of the slips' detected rate and the share of
    non-slip trials that never raised an early alarm: a trial-label score such as
    slip-or-wiggle; NaN without both kinds of trial).
    """
    slips = [e for e in events if e.slipped is True]
    quiet = [not e.early_alarm for e in events if e.slipped is False]
    detected = [e for e in slips if e.detected]
    early_defined = [e for e in events if e.early_alarm is not None]
    delays = np.asarray([e.delay_ms for e in detected if math.isfinite(e.delay_ms)])
    minutes = sum(e.nonslip_s for e in events) / 60.0
    n_dist = sum(e.disturbances for e in events)
    costs = np.asarray([trial_cost(e, cost) for e in events], dtype=np.float64)
    costs = costs[np.isfinite(costs)]
    return {
        "detected_rate": len(detected) / len(slips) if slips else math.nan,
        "early_alarm_rate": (
            sum(bool(e.early_alarm) for e in early_defined) / len(early_defined)
            if early_defined
            else math.nan
        ),
        "false_alarms_per_min": (
            sum(e.false_alarms for e in events) / minutes if minutes > 0 else math.nan
        ),
        "alarms_per_disturbance": (
            sum(e.disturbances_fired for e in events) / n_dist if n_dist else math.nan
        ),
        "delay_ms": float(np.median(delays)) if len(delays) else math.nan,
        "delay_p90_ms": float(np.percentile(delays, 90)) if len(delays) else math.nan,
        "n_slips": len(slips),
        "missed": len(slips) - len(detected),
        "event_trials": len(costs),
        "unknown_onset_trials": sum(not math.isfinite(e.onset_s) for e in slips),
        "disturbances": n_dist,
        "cost": float(costs.mean()) if len(costs) else math.nan,
        "cost_without_detector": (
            cost.miss * len(slips) / len(costs) if len(costs) else math.nan
        ),
        "trial_balanced_accuracy": (
            (len(detected) / len(slips) + sum(quiet) / len(quiet)) / 2
            if slips and quiet
            else math.nan
        ),
    }


def events_table(events: Sequence[TrialEvents], cost: Cost) -> pd.DataFrame:
    """One row per trial: every :class:`TrialEvents` field and its ``cost``."""
    rows = [{**asdict(e), "cost": trial_cost(e, cost)} for e in events]
    return pd.DataFrame(rows, columns=[*TrialEvents.__dataclass_fields__, "cost"])


def evaluate_point(
    truths: Sequence[TrialTruth],
    scores: Sequence[ArrayLike],
    threshold: float,
    debounce_k: int,
    cost: Cost,
    *,
    tolerance_s: float = 0.0,
) -> tuple[dict[str, Any], list[TrialEvents]]:
    """:func:`summarise` of every trial at one operating point, and the trials."""
    events = [
        trial_events(tr, s, threshold, debounce_k, tolerance_s=tolerance_s)
        for tr, s in zip(truths, scores, strict=True)
    ]
    return summarise(events, cost), events


def threshold_grid(
    scores: Iterable[ArrayLike],
    n: int = DEFAULT_THRESHOLDS,
    extra: Iterable[float] = (),
) -> FloatArray:
    """Candidate thresholds: ``n`` quantiles of the finite scores (half spread evenly,
    half towards the top, where the rare slip samples lie) plus ``extra`` (e.g. the
    detector's own ROC choice), unique and sorted."""
    pooled = [np.asarray(s, dtype=np.float64).ravel() for s in scores]
    finite = np.concatenate(pooled) if pooled else np.empty(0)
    finite = finite[np.isfinite(finite)]
    extras = np.asarray([v for v in extra if math.isfinite(float(v))], dtype=np.float64)
    if not len(finite):
        return np.unique(extras)
    half = max(n // 2, 1)
    tail = 1.0 - np.geomspace(0.5, 1.0 / max(len(finite), 2), half)
    levels = np.unique(np.clip(np.concatenate([np.linspace(0, 1, half), tail]), 0, 1))
    return np.unique(np.concatenate([np.quantile(finite, levels), extras]))


@dataclass
class OperatingPoint:
    """The chosen (threshold, debounce) and what it did on the trials it was chosen on.

    Attributes
    ----------
    threshold : float
    debounce_k : int
    summary : dict
        :func:`summarise` at that point on the choosing trials.
    within_limits : bool
        False when no candidate met the limits (the cheapest one is kept, flagged).
    note : str
        Why, when not within the limits (else "").
    candidates : int
        Grid points tried.
    chosen_on : list of str
        The trial ids the point was chosen on (never the test split's).
    """

    threshold: float
    debounce_k: int
    summary: dict[str, Any]
    within_limits: bool = True
    note: str = ""
    candidates: int = 0
    chosen_on: list[str] = field(default_factory=list)

    def record(self, source: str) -> dict[str, Any]:
        """JSON-able record for ``metrics.json`` (``source``: where it was chosen)."""
        return {
            "threshold": float(self.threshold),
            "debounce_k": int(self.debounce_k),
            "from": source,
            "within_limits": bool(self.within_limits),
            "note": self.note,
            "candidates": int(self.candidates),
            "validation": dict(self.summary),
            "chosen_on": list(self.chosen_on),
        }


def choose_operating_point(
    truths: Sequence[TrialTruth],
    scores: Sequence[ArrayLike],
    *,
    thresholds: ArrayLike,
    debounce_ks: Sequence[int] = DEFAULT_DEBOUNCE,
    cost: Cost | None = None,
    limits: Limits | None = None,
    tolerance_s: float = 0.0,
) -> OperatingPoint:
    """The (threshold, debounce) of lowest mean cost on ``truths`` among the points within ``limits``.

    A point qualifies when it is within the limits and costs less than no detector
    (``cost_without_detector``: a point that never alarms, or alarms only where it
    should not, is no operating point). Ties of cost go to the smaller debounce (an
    earlier alarm), then to the middle of the tied thresholds (the middle of a plateau,
    not its edge). With no point qualifying, the point nearest the limits among those
    that beat no detector (least total excess of the rates over their limits, then
    cheapest) is returned with ``within_limits`` False and a note; the cheapest point
    alone would be one that alarms everywhere, which an early-alarm weight below a
    miss makes cheap.

    Parameters
    ----------
    truths, scores : sequences
        Validation trials and their (out-of-fold) scores, one array per trial.
    thresholds : array_like
        Candidate thresholds (:func:`threshold_grid`).
    debounce_ks : sequence of int
        Candidate debounce k.
    cost, limits : Cost, Limits
        The cost weights and the limits (defaults: :class:`Cost`, :class:`Limits`).
    tolerance_s : float
        Disturbance tolerance (s).

    Raises
    ------
    ValueError
        No candidate (empty thresholds or debounce list).
    """
    cost = cost or Cost()
    limits = limits or Limits()
    thr = np.unique(np.asarray(thresholds, dtype=np.float64))
    ks = sorted({int(k) for k in debounce_ks})
    if not len(thr) or not ks:
        raise ValueError("no operating-point candidates (thresholds or debounce_ks)")
    grid: list[tuple[float, int, dict[str, Any], str | None]] = []
    for k in ks:
        for th in thr:
            summary, _ = evaluate_point(
                truths, scores, float(th), k, cost, tolerance_s=tolerance_s
            )
            grid.append((float(th), k, summary, _disqualified(summary, limits)))

    def best(points: list[tuple[float, int, dict[str, Any], str | None]]) -> int:
        c = np.asarray([_float(p[2]["cost"]) for p in points])
        c = np.where(np.isfinite(c), c, np.inf)
        low = c.min()
        tied = [i for i in range(len(points)) if c[i] <= low + 1e-12]
        k_min = min(points[i][1] for i in tied)
        tied = [i for i in tied if points[i][1] == k_min]
        return tied[len(tied) // 2]

    ok = [p for p in grid if p[3] is None]
    ids = [str(tr.trial_id) for tr in truths]
    if ok:
        th, k, summary, _ = ok[best(ok)]
        return OperatingPoint(th, k, summary, True, "", len(grid), ids)
    useful = [p for p in grid if no_better_than_nothing(p[2]) is None]
    if useful:
        excess = np.asarray([limits.excess(p[2]) for p in useful])
        near = [
            p for p, e in zip(useful, excess, strict=True) if e <= excess.min() + 1e-12
        ]
        th, k, summary, why = near[best(near)]
        what = "the one nearest the limits"
    else:
        th, k, summary, why = grid[best(grid)]
        what = "the cheapest one"
    return OperatingPoint(
        th,
        k,
        summary,
        False,
        f"no candidate within the limits that beats no detector; {what} ({why})",
        len(grid),
        ids,
    )


def no_better_than_nothing(summary: Mapping[str, Any]) -> str | None:
    """``costs 1.05 per trial, no less than no detector (1.00)`` when the summary's cost
    is not below ``cost_without_detector`` (None: it is, or either is undefined)."""
    c = _float(summary.get("cost"))
    floor = _float(summary.get("cost_without_detector"))
    if not (math.isfinite(c) and math.isfinite(floor)) or c < floor - 1e-12:
        return None
    return (
        f"costs {c:.3g} per trial, no less than no detector ({floor:.3g}: every slip "
        "missed, no alarm)"
    )


def _disqualified(summary: Mapping[str, Any], limits: Limits) -> str | None:
    return limits.breach(summary) or no_better_than_nothing(summary)


__all__ = [
    "DEFAULT_DEBOUNCE",
    "DEFAULT_THRESHOLDS",
    "OPERATING_POINT_KEYS",
    "SLIPPED_LABEL",
    "SUMMARY_COLUMNS",
    "Cost",
    "Limits",
    "OperatingPoint",
    "TrialEvents",
    "TrialTruth",
    "alarm_indices",
    "choose_operating_point",
    "evaluate_point",
    "events_table",
    "no_better_than_nothing",
    "parse_cost",
    "parse_limits",
    "parse_operating_point",
    "slipped_of",
    "summarise",
    "threshold_grid",
    "trial_cost",
    "trial_events",
]
