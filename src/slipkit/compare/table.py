"""The unified comparison table: one row per estimator, its scores and its costs, and the Pareto front."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

from slipkit.compare.adapters import ROW_COLUMNS

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
    {"rmse", "smse", "delay_ms", "missed", "false_alarms_per_min", "fpr", "fnr"}
)


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
    df["pareto"] = pareto_front(
        df["p50_us"].to_numpy(float), df["score"].to_numpy(float)
    )
    extra = sorted(c for c in df.columns if c not in COLUMNS)
    df = df[[*COLUMNS, *extra]]
    df.attrs["primary"] = primary
    return df


def best_row(df: pd.DataFrame) -> pd.Series | None:
    """The row to deploy: the highest score among exported rows within budget, else among exported, else any."""
    for mask in (
        df["within_budget"].eq(True),
        df["export"].eq("ok"),
        pd.Series(True, index=df.index),
    ):
        cand = df[mask & np.isfinite(df["score"].to_numpy(float))]
        if len(cand):
            # ties: the cheaper one (p50), then the table order
            order = cand.assign(_c=cand["p50_us"].fillna(np.inf)).sort_values(
                ["score", "_c"], ascending=[False, True], kind="stable"
            )
            return order.iloc[0].drop(labels="_c")
    return None


__all__ = [
    "COLUMNS",
    "LOWER_IS_BETTER",
    "best_row",
    "build_table",
    "pareto_front",
    "score_of",
]
