"""The unified comparison table: one row per estimator, its scores and its costs, and the Pareto front."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

from slipkit.compare.adapters import ROW_COLUMNS
from slipkit.errors import SlipkitError
from slipkit.evaluate.events import Cost, no_better_than_nothing, parse_cost
from slipkit.runtime.budget import (
    BORDERLINE,
    P99_BLOCKS,
    block_p99,
    judge_latency,
    judge_p99,
    quiet_p99,
)

#: columns of ``metrics.csv`` before the per-axis regression columns
COLUMNS = (
    "estimator",
    "kind",
    "class",
    *ROW_COLUMNS,
    "score",
    "fit_s",
    "fit_calls",
    "task_s",
    "p50_us",
    "p99_us",
    "budget_p99_us",
    "frame_period_us",
    "within_budget",
    "pareto",
    "export",
)

#: primary columns where lower is better: the score is their negative
LOWER_IS_BETTER = frozenset(
    {
        "rmse",
        "smse",
        "delay_ms",
        "delay_p90_ms",
        "missed",
        "false_alarms_per_min",
        "fpr",
        "fnr",
        "cost",
        "early_alarm_rate",
        "alarms_per_disturbance",
    }
)


#: units of the primary metrics that carry one (rates and SMSE are dimensionless; the
#: cost is in units of a missed slip)
METRIC_UNITS = {
    "delay_ms": "ms",
    "delay_p90_ms": "ms",
    "false_alarms_per_min": "1/min",
    "missed": "slips",
}
#: units of a regression's per-axis columns ``rmse_<axis>`` (BioTac force, SlipTack speed)
AXIS_UNITS = {"x": "N", "y": "N", "z": "N", "speed": "mm/s"}


def _grouped(unit: str) -> str:
    """``unit`` in parentheses when it is compound (``mm/s`` -> ``(mm/s)``), else as is."""
    return f"({unit})" if any(c in unit for c in "/* ") else unit


def per_unit(numerator: str, denominator: str) -> str:
    """The unit ``numerator`` per ``denominator``, written unambiguously.

    ``per_unit("us", "N") == "us/N"``, ``per_unit("us", "mm/s") == "us/(mm/s)"``,
    ``per_unit("1", "N/mm") == "1/(N/mm)"``; an empty denominator leaves the numerator.
    Plain string composition: no unit library is needed for a division.
    """
    if not denominator:
        return numerator
    return f"{numerator or '1'}/{_grouped(denominator)}"


def metric_unit(primary: str, columns: Sequence[str] = ()) -> str:
    """The unit of the metric ``primary`` ("" when dimensionless or unknown).

    ``rmse`` takes the unit its per-axis columns (``rmse_<axis>`` in ``columns``) share.
    """
    if primary in METRIC_UNITS:
        return METRIC_UNITS[primary]
    if primary.startswith("rmse_"):
        return AXIS_UNITS.get(primary[len("rmse_") :], "")
    if primary == "rmse":
        found = {
            AXIS_UNITS.get(c[len("rmse_") :], "")
            for c in columns
            if c.startswith("rmse_") and not c.endswith(("_std", "_ci"))
        }
        return found.pop() if len(found) == 1 else ""
    return ""


def score_of(row: pd.Series | dict[str, object], primary: str) -> float:
    """The comparison's score of one row: ``primary``, negated when lower is better."""
    value = row.get(primary, math.nan)
    v = math.nan if value is None else float(value)  # type: ignore[arg-type]
    return (
        -v
        if primary in LOWER_IS_BETTER or primary.startswith(("rmse_", "smse_"))
        else v
    )


def pareto_front(cost: ArrayLike, score: ArrayLike) -> np.ndarray:
    """Which points no other point beats on both axes (lower cost, higher score).

    A point is on the front when no other point has cost <= and score >= with at
    least one strict. Points with a non-finite cost or score are never on it.
    Hand-written: a comparison has a handful of points, and neither numpy nor
    scikit-learn offers a non-dominated filter.

    Parameters
    ----------
    cost : sequence of float
        Compute per frame (e.g. p50 us); lower is better.
    score : sequence of float
        Accuracy-like score; higher is better.

    Returns
    -------
    ndarray of bool
        True for the points on the front.
    """
    c = np.asarray(cost, dtype=np.float64)
    s = np.asarray(score, dtype=np.float64)
    if c.shape != s.shape:
        raise ValueError(f"cost and score differ in length: {c.shape} vs {s.shape}")
    ok = np.isfinite(c) & np.isfinite(s)
    front = np.zeros(len(c), dtype=bool)
    for i in np.flatnonzero(ok):
        others = ok.copy()
        others[i] = False
        dominated = (
            others & (c <= c[i]) & (s >= s[i]) & ((c < c[i]) | (s > s[i]))
        ).any()
        front[i] = not dominated
    return front


def build_table(rows: Sequence[dict[str, object]], primary: str) -> pd.DataFrame:
    """The rows as a DataFrame in :data:`COLUMNS` order, with ``score`` and ``pareto`` filled."""
    df = pd.DataFrame(list(rows))
    for col in COLUMNS:
        if col not in df:
            df[col] = math.nan
    df["score"] = [score_of(r, primary) for _, r in df.iterrows()]
    # on p99, the percentile the budget is checked on (and the Pareto plot's x axis)
    df["pareto"] = pareto_front(
        df["p99_us"].to_numpy(float), df["score"].to_numpy(float)
    )
    extra = sorted(c for c in df.columns if c not in COLUMNS)
    df = df[[*COLUMNS, *extra]]
    df.attrs["primary"] = primary
    return df


def is_borderline(margin: float) -> bool:
    """True when the latency rule calls p99 / budget ``margin`` borderline
    (:data:`~slipkit.runtime.budget.BORDERLINE` < margin <= its inverse)."""
    return judge_p99(margin, 1.0).status == "borderline"


@dataclass(frozen=True)
class DeployChoice:
    """Which estimator a comparison recommends, and why the higher-scoring ones were passed over.

    Attributes
    ----------
    row : pandas.Series or None
        The recommended row; when none meets the budget, the best-scoring exportable row
        (else the best-scoring row), shown but not recommended. None without any score.
    recommended : bool
        True when ``row`` is exported and the latency rule passes its p99 (us) against
        its p99 budget (us): within, or borderline (flagged).
    passed_over : tuple of (str, str)
        ``(estimator, reason)`` for each row that scores at least as high as ``row`` (ranked
        before it) and was not chosen; with ``recommended`` False, every row's reason in
        ranking order, ``row``'s own among them.
    margin : float
        ``row``'s p99 / p99 budget (dimensionless; NaN when not measured).
    tied : tuple of str
        The deployable rows whose ranking metric ties with ``row``'s (within the spread
        over seeds, :func:`ties`), ``row`` excluded.
    tie_break : str
        What broke the tie (``lower delay (12 ms against 30 ms)``); "" without a tie.
    n_seeds : int
        Seeds the means are over (1: no ties are declared).
    """

    row: pd.Series | None
    recommended: bool
    passed_over: tuple[tuple[str, str], ...]
    margin: float
    tied: tuple[str, ...] = ()
    tie_break: str = ""
    n_seeds: int = 1

    @property
    def borderline(self) -> bool:
        """True when the latency rule calls ``row``'s p99 borderline (passes, flagged)."""
        return is_borderline(self.margin)


def _rejection(
    r: pd.Series,
    max_alarms_per_disturbance: float | None = None,
    max_early_alarm_rate: float | None = None,
) -> str | None:
    """Why ``r`` cannot be recommended (None when it can): not exported, a trial cost
    no lower than no detector's (every slip missed), an early alarm in more than
    ``max_early_alarm_rate`` of the test trials, firing on more than
    ``max_alarms_per_disturbance`` of the test disturbances, or p99 over budget.

    An exported row's rates are named before its p99: a rate is a property of the
    estimator on the data, the p99 a measurement a busy machine can move, so the reason
    a report gives for a knock-prone row does not change between re-runs.
    """
    deploy = _deploy_rejection(r)
    if r.get("export") != "ok":
        return deploy
    return (
        no_better_than_nothing({str(k): v for k, v in r.items()})
        or _early_rejection(r, max_early_alarm_rate)
        or _disturbance_rejection(r, max_alarms_per_disturbance)
        or deploy
    )


def _early_rejection(r: pd.Series, limit: float | None) -> str | None:
    """``early alarms in 71 % of test trials > 25 %`` when ``early_alarm_rate`` is above
    ``limit``; None without a limit or where the rate is not defined."""
    value = r.get("early_alarm_rate", math.nan)
    try:
        rate = math.nan if value is None else float(value)
    except (TypeError, ValueError):
        rate = math.nan
    if limit is None or not math.isfinite(rate) or rate <= limit + 1e-12:
        return None
    return f"early alarms in {rate * 100:.0f} % of test trials > {limit * 100:g} %"


def _disturbance_rejection(r: pd.Series, limit: float | None) -> str | None:
    """``fires on 54 % of disturbances > 10 %`` when ``alarms_per_disturbance`` is above
    ``limit`` (a fraction); None without a limit or where no disturbance was counted."""
    rate = disturbance_rate(r)
    if limit is None or not math.isfinite(rate) or rate <= limit:
        return None
    return f"fires on {rate * 100:.0f} % of disturbances > {limit * 100:g} %"


def disturbance_rate(r: pd.Series | dict[str, object]) -> float:
    """The row's ``alarms_per_disturbance`` (fraction of test disturbances it fired on;
    NaN when the data marks none)."""
    value = r.get("alarms_per_disturbance", math.nan)
    try:
        return math.nan if value is None else float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan


#: the keys a comparison's ``verdict:`` mapping may hold: the cost of a detection
#: comparison's trial events and the limits on top of the budget
VERDICT_KEYS = ("cost", "max_early_alarm_rate", "max_alarms_per_disturbance")
#: the limits a verdict applies when its ``verdict:`` does not name them (null: none)
DEFAULT_LIMITS: dict[str, float | None] = {"max_early_alarm_rate": 0.25}


def verdict_limits(
    node: Mapping[str, Any] | None, where: str = "comparison.verdict"
) -> dict[str, float | None]:
    """A comparison's ``verdict:`` mapping checked; its limits as keyword arguments of
    :func:`choose_deploy`.

    ``max_early_alarm_rate`` (default 0.25): a row with an early alarm in more than that
    share of the test trials is passed over; ``max_alarms_per_disturbance``: a row that
    fires on more than that share of the test disturbances is passed over; null: no
    limit. ``cost`` (the trial cost's weights, :func:`verdict_cost`) is checked here
    too but is not a limit. A row where a rate is not defined is not held to it.

    Raises
    ------
    SlipkitError
        Not a mapping, an unknown key, a limit that is not a number in [0, 1], or a
        bad cost; the message names ``where`` and the key.
    """
    out: dict[str, float | None] = dict(DEFAULT_LIMITS)
    if node is None:
        return out
    if not isinstance(node, Mapping):
        raise SlipkitError(
            f"{where}: must be a mapping such as {{max_alarms_per_disturbance: 0.10}}; "
            f"got {node!r}"
        )
    for key, value in node.items():
        if key not in VERDICT_KEYS:
            raise SlipkitError(
                f"{where}.{key}: unknown verdict key; known: {list(VERDICT_KEYS)}"
            )
        if key == "cost":
            verdict_cost(node, where)
            continue
        if value is not None and (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not 0.0 <= float(value) <= 1.0
        ):
            raise SlipkitError(
                f"{where}.{key}: must be a fraction in [0, 1] (0.10 = 10 %) or null; "
                f"got {value!r}"
            )
        out[str(key)] = None if value is None else float(value)
    return out


def verdict_cost(
    node: Mapping[str, Any] | None, where: str = "comparison.verdict"
) -> Cost:
    """The trial cost's weights of a comparison's ``verdict:`` (``cost: {miss,
    early_alarm, delay_ms}``; absent: :class:`slipkit.evaluate.events.Cost`'s defaults)."""
    node = node if isinstance(node, Mapping) else {}
    return parse_cost(node.get("cost"), f"{where}.cost")


def _deploy_rejection(r: pd.Series) -> str | None:
    """Not exported, or p99 over budget by the latency rule (None: deployable; a
    borderline p99 passes, flagged by :attr:`DeployChoice.borderline`)."""
    note = r.get("export")
    if note != "ok":
        text = (
            ""
            if note is None or (isinstance(note, float) and math.isnan(note))
            else str(note)
        )
        return (
            text if text.startswith("not ") else f"not exported: {text or 'no bundle'}"
        )
    p99 = float(r.get("p99_us", math.nan))
    budget = float(r.get("budget_p99_us", math.nan))
    if not (math.isfinite(p99) and math.isfinite(budget)):
        # no numbers to compare: only the cost step's own within_budget flag can vouch
        ok = r.get("within_budget")
        measured = isinstance(ok, bool | np.bool_) and bool(ok)
        return None if measured else "p99 not measured against a budget"
    judged = judge_p99(p99, budget)
    if not judged.passed:
        return f"p99 {p99:.0f} us > {budget:.4g} us budget: {judged.status}"
    return None


def choose_deploy(
    df: pd.DataFrame,
    *,
    max_alarms_per_disturbance: float | None = None,
    max_early_alarm_rate: float | None = None,
) -> DeployChoice:
    """The deploy rule: the best score among exported rows within the limits and the budget.

    Rows are ranked by ``score`` (higher first; a detection comparison's score is minus
    its trial cost), ties by p99 (lower first), then table order. An over-budget or
    unexportable row is never recommended, nor one over a limit (an early alarm in more
    than ``max_early_alarm_rate`` of the test trials, firing on more than
    ``max_alarms_per_disturbance`` of the test disturbances); each one ranked above the
    choice is listed with its reason. Among the rows that qualify, those whose ranking
    metric ties with the best one's (over several seeds: within the spread,
    :func:`ties`) are one tie, broken by :data:`TIE_BREAKERS` (earlier, fewer false
    alarms, cheaper per frame). When no row qualifies, the best-scoring exported row
    (else the best-scoring row) is returned with ``recommended`` False.

    Parameters
    ----------
    df : pandas.DataFrame
        A :func:`build_table` table (``score``, ``export``, ``p99_us``, ``budget_p99_us``,
        the rates where the data defines them; with seeds ``<primary>_std``).
    max_alarms_per_disturbance, max_early_alarm_rate : float or None
        The comparison's limits (fractions 0..1, :func:`verdict_limits`); None: no
        limit. A row where the rate is not defined is not held to it.

    Returns
    -------
    DeployChoice
    """
    n_seeds = _n_seeds(df)
    scored = df[np.isfinite(df["score"].to_numpy(float))]
    if scored.empty:
        return DeployChoice(None, False, (), math.nan, n_seeds=n_seeds)
    ranked = (
        scored.assign(_c=scored["p99_us"].astype(float).fillna(np.inf))
        .sort_values(["score", "_c"], ascending=[False, True], kind="stable")
        .drop(columns="_c")
    )
    passed: list[tuple[str, str]] = []
    eligible: list[pd.Series] = []
    for _, r in ranked.iterrows():
        why = _rejection(r, max_alarms_per_disturbance, max_early_alarm_rate)
        if why is None:
            eligible.append(r)
        elif not eligible:
            passed.append((str(r["estimator"]), why))
    if eligible:
        primary = str(df.attrs.get("primary", ""))
        best = eligible[0]
        tied = [r for r in eligible[1:] if ties(best, r, primary)]
        chosen, broken_by = break_tie([best, *tied])
        others = tuple(
            str(r["estimator"])
            for r in [best, *tied]
            if str(r["estimator"]) != str(chosen["estimator"])
        )
        return DeployChoice(
            chosen,
            True,
            tuple(passed),
            _margin(chosen),
            tied=others,
            tie_break=broken_by if others else "",
            n_seeds=n_seeds,
        )
    exported = np.flatnonzero(ranked["export"].eq("ok").to_numpy())
    pos = int(exported[0]) if len(exported) else 0
    row = ranked.iloc[pos]
    # nothing qualifies: every row's reason, the shown row's own among them
    return DeployChoice(row, False, tuple(passed), _margin(row), n_seeds=n_seeds)


#: what breaks a tie, in order: (column, what lower means, unit)
TIE_BREAKERS = (
    ("delay_ms", "lower delay", "ms"),
    ("early_alarm_rate", "fewer early alarms", "%"),
    ("false_alarms_per_min", "fewer false alarms", "/min"),
    ("p99_us", "cheaper per frame (p99)", "us"),
)


def _n_seeds(df: pd.DataFrame) -> int:
    if "n_seeds" not in df or df.empty:
        return 1
    n = pd.to_numeric(df["n_seeds"], errors="coerce").max()
    return int(n) if math.isfinite(float(n)) else 1


def _value(r: pd.Series, column: str) -> float:
    value = r.get(column, math.nan)
    try:
        return math.nan if value is None else float(value)
    except (TypeError, ValueError):
        return math.nan


def ties(a: pd.Series, b: pd.Series, primary: str) -> bool:
    """Whether rows ``a`` and ``b`` tie on the ranking metric ``primary``: over several
    seeds, ``|mean_a - mean_b| <= max(std_a, std_b)`` (the seeds' spread); with one seed
    (no ``<primary>_std``) never."""
    if not primary:
        return False
    sa, sb = _value(a, f"{primary}_std"), _value(b, f"{primary}_std")
    if not (math.isfinite(sa) or math.isfinite(sb)):
        return False
    spread = max(v for v in (sa, sb) if math.isfinite(v))
    ma, mb = _value(a, primary), _value(b, primary)
    return bool(math.isfinite(ma) and math.isfinite(mb) and abs(ma - mb) <= spread)


def _shown(v: float, unit: str) -> str:
    if not math.isfinite(v):
        return "none"
    return f"{v * 100:.0f} %" if unit == "%" else f"{v:.3g} {unit}"


#: p99s within this factor of the lowest are one timing: a shared machine's p99 moves
#: this much between runs (the latency rule's borderline band), so such a difference
#: never breaks a tie and the verdict does not flip with the machine's load
P99_TIE = 1.25


def _table_first(rows: Sequence[pd.Series]) -> pd.Series:
    """The row that comes first in the comparison's own order (its table index)."""
    order = [r.name for r in rows]
    if all(isinstance(i, (int, np.integer)) for i in order):
        return rows[int(np.argmin(np.asarray(order, dtype=np.int64)))]
    return rows[0]


def _same_p99(row: pd.Series, p99: float, fastest: pd.Series) -> bool:
    """Whether ``row``'s p99 is one timing with the ``fastest`` row's: within
    :data:`P99_TIE` of it, or no further from it than the larger spread over seeds of
    the two (``p99_us_std``): a detector whose p99 swings between seeds on a shared
    machine is not slower for one run's draw."""
    low = _value(fastest, "p99_us")
    if not math.isfinite(p99):
        return False
    if p99 <= low * P99_TIE:
        return True
    spread = max(_value(row, "p99_us_std"), _value(fastest, "p99_us_std"))
    return math.isfinite(spread) and p99 - low <= spread


def break_tie(rows: Sequence[pd.Series]) -> tuple[pd.Series, str]:
    """The row that wins a tie by :data:`TIE_BREAKERS`, and what broke it.

    Each breaker in turn keeps the rows of the lowest value (a row without the value
    loses to one with it; p99s within :data:`P99_TIE` of the lowest, or within the
    seeds' spread of it, count as equal: :func:`_same_p99`);
    the first breaker that leaves fewer rows is named, e.g. ``lower delay (12 ms
    against 30 ms for `b`)``. Rows still equal after every breaker: the first in the
    comparison's order, so two runs choose the same row whatever their timings.
    """
    left = list(rows)
    named = ""
    for column, what, unit in TIE_BREAKERS:
        vals = [_value(r, column) for r in left]
        finite = [v for v in vals if math.isfinite(v)]
        if not finite:
            continue
        low = min(finite)
        if column == "p99_us":
            fastest = left[vals.index(low)]
            keep = [
                r for r, v in zip(left, vals, strict=True) if _same_p99(r, v, fastest)
            ]
        else:
            keep = [r for r, v in zip(left, vals, strict=True) if v <= low]
        if len(keep) < len(left) and not named:
            runner = next((r for r in left if not any(r is k for k in keep)), left[0])
            other = _value(runner, column)
            named = (
                f"{what} ({_shown(low, unit)} against {_shown(other, unit)} for "
                f"`{runner['estimator']}`)"
            )
        left = keep
        if len(left) == 1:
            break
    if named:
        return _table_first(left), named
    return _table_first(left), "the comparison's order (every tie-breaker equal)"


def _margin(r: pd.Series) -> float:
    p99 = float(r.get("p99_us", math.nan))
    budget = float(r.get("budget_p99_us", math.nan))
    return p99 / budget if math.isfinite(budget) and budget > 0 else math.nan


#: columns of a per-seed row that are not averaged over seeds (text, flags, the seed)
_NOT_AVERAGED = frozenset(
    {"estimator", "kind", "class", "export", "within_budget", "pareto", "seed", "score"}
)


def seed_table(
    per_seed: pd.DataFrame,
    latencies: dict[str, np.ndarray],
    primary: str,
    confidence: float = 0.95,
    unpaced: dict[str, np.ndarray] | None = None,
) -> pd.DataFrame:
    """The comparison table of several seeds: one row per estimator, means with their spread.

    Every numeric column is averaged over the seeds (:func:`slipkit.evaluate.aggregate.aggregate`)
    and its sample standard deviation kept as ``<column>_std`` (the CI half-width as
    ``<column>_ci``); ``n_seeds`` counts the seeds. ``p50_us`` / ``p99_us`` are taken on
    all seeds' frames pooled (``latencies``: estimator -> latencies in us, in order),
    judged by the latency rule (:func:`slipkit.runtime.budget.judge_latency`). ``export`` is ``ok``
    only when every seed's bundle exported (else the first seed's reason). The score is
    that of the mean ``primary`` (:func:`build_table`).

    Parameters
    ----------
    per_seed : pandas.DataFrame
        One :func:`build_table`-style row per (estimator, seed), with a ``seed`` column.
    latencies : dict of str to ndarray
        Every seed's timed decisions of each estimator, concatenated, us.
    primary : str
        The comparison's primary metric.
    confidence : float
        Confidence level of the ``_ci`` columns.
    unpaced : dict of str to ndarray, optional
        The back-to-back replays' latencies (us) of the estimators that had one
        (:attr:`slipkit.compare.costs.DeployCost.unpaced_latency_us`), all seeds
        concatenated: ``p99_unpaced_us`` is their pooled p99 as well.

    Returns
    -------
    pandas.DataFrame
        A :func:`build_table` table with the extra ``_std``, ``_ci`` and ``n_seeds`` columns.
    """
    from slipkit.evaluate.aggregate import aggregate

    numeric = [
        c
        for c in per_seed.select_dtypes(include="number").columns
        if c not in _NOT_AVERAGED
    ]
    agg = aggregate(per_seed, ["estimator"], numeric, confidence=confidence)
    stats = {str(r["estimator"]): r for r in agg.to_dict("records")}
    rows: list[dict[str, object]] = []
    for est, g in per_seed.groupby("estimator", sort=False):
        first = g.iloc[0]
        bad = [str(e) for e in g["export"] if e != "ok"]
        st = stats[str(est)]
        row: dict[str, object] = {
            "estimator": est,
            "kind": first["kind"],
            "class": first["class"],
            "export": bad[0] if bad else "ok",
            "n_seeds": int(st["n"]),
        }
        for c in numeric:
            for part in ("std", "ci"):
                row[f"{c}_{part}"] = st[f"{c}_{part}"]
            row[c] = st[f"{c}_mean"]
        for c in per_seed.columns:  # text (e.g. operating_point_from): each value once
            if c not in row and c not in numeric and c not in _NOT_AVERAGED:
                seen = [str(v) for v in dict.fromkeys(g[c]) if isinstance(v, str)]
                if seen:
                    row[c] = " | ".join(seen)
        lat = np.asarray(latencies.get(str(est), np.zeros(0)), dtype=np.float64)
        if not bad and len(lat):
            budget = float(first.get("budget_p99_us", math.nan))
            judged = judge_latency(lat, budget)
            row["p50_us"] = float(np.percentile(lat, 50))
            row["p99_us"] = block_p99(lat)
            row["p99_quiet_us"] = quiet_p99(lat)
            row["within_budget"] = judged.passed if math.isfinite(budget) else None
        else:
            row["p50_us"] = row["p99_us"] = row["p99_quiet_us"] = math.nan
            row["within_budget"] = None
        if "p99_unpaced_us" in row:  # not a mean over seeds: the pooled p99, as p99_us
            back = np.asarray((unpaced or {}).get(str(est), []), dtype=np.float64)
            row["p99_unpaced_us"] = block_p99(back) if not bad else math.nan
        rows.append(row)
    return build_table(rows, primary)


def best_row(
    df: pd.DataFrame,
    *,
    max_alarms_per_disturbance: float | None = None,
    max_early_alarm_rate: float | None = None,
) -> pd.Series | None:
    """The row :func:`choose_deploy` returns (recommended or, when none meets the budget, shown)."""
    return choose_deploy(
        df,
        max_alarms_per_disturbance=max_alarms_per_disturbance,
        max_early_alarm_rate=max_early_alarm_rate,
    ).row


__all__ = [
    "AXIS_UNITS",
    "BORDERLINE",
    "COLUMNS",
    "DEFAULT_LIMITS",
    "LOWER_IS_BETTER",
    "METRIC_UNITS",
    "P99_BLOCKS",
    "TIE_BREAKERS",
    "VERDICT_KEYS",
    "DeployChoice",
    "best_row",
    "block_p99",
    "break_tie",
    "build_table",
    "choose_deploy",
    "disturbance_rate",
    "is_borderline",
    "metric_unit",
    "pareto_front",
    "per_unit",
    "quiet_p99",
    "score_of",
    "seed_table",
    "ties",
    "verdict_cost",
    "verdict_limits",
]
