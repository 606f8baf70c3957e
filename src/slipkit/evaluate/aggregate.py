"""One table from repeated runs: per group, the mean, spread and confidence interval of each metric.

Seeds, objects or folds of the same comparison give one row each; :func:`aggregate` folds them
into one row per group (e.g. per estimator) so a verdict rests on the mean over runs rather
than on one draw, and the report can show the spread.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from slipkit.errors import SlipkitError


def _metric_columns(
    df: pd.DataFrame, by: Sequence[str], metrics: Sequence[str] | None
) -> list[str]:
    """The metric columns to aggregate: the named ones (checked) or every numeric column."""
    if metrics is None:
        numeric = df.select_dtypes(include="number").columns
        return [c for c in numeric if c not in by]
    out = []
    for m in metrics:
        if m not in df.columns:
            raise SlipkitError(
                f"aggregate: metric {m!r} is not a column (columns: {', '.join(map(str, df.columns))})"
            )
        if m in by:
            raise SlipkitError(f"aggregate: {m!r} is both a group column and a metric")
        col = df[m]
        if not (pd.api.types.is_numeric_dtype(col) or pd.api.types.is_bool_dtype(col)):
            raise SlipkitError(
                f"aggregate: metric {m!r} is not numeric (dtype {col.dtype})"
            )
        out.append(m)
    return out


def aggregate(
    df: pd.DataFrame,
    by: Sequence[str],
    metrics: Sequence[str] | None = None,
    confidence: float = 0.95,
) -> pd.DataFrame:
    """Per group of ``by``, the count, mean, std and CI half-width of each metric.

    The CI is Student's t interval of the mean: half-width
    ``t_{(1 + confidence) / 2, k - 1} * std / sqrt(k)`` with ``k`` the metric's non-NaN
    values in the group and ``std`` the sample standard deviation (ddof 1). With one
    value the std and half-width are NaN: one run says nothing about its spread. NaNs
    (a metric a run could not measure) are left out of that metric only.

    Parameters
    ----------
    df : pandas.DataFrame
        One row per run (seed, object, fold ...) and group.
    by : sequence of str
        The group columns (e.g. ``["estimator"]``); groups keep their first-seen order.
    metrics : sequence of str, optional
        The columns to aggregate (numeric or boolean; a boolean's mean is the fraction
        True). Default: every numeric column not in ``by``.
    confidence : float
        Confidence level of the interval, in (0, 1).

    Returns
    -------
    pandas.DataFrame
        One row per group: the ``by`` columns, ``n`` (rows in the group), then
        ``<metric>_mean``, ``<metric>_std``, ``<metric>_ci`` per metric, in the metrics'
        order. Each keeps the metric's unit.

    Raises
    ------
    SlipkitError
        A group or metric column is missing or not numeric, or ``confidence`` is not in
        (0, 1).
    """
    by = list(by)
    if not by:
        raise SlipkitError("aggregate: by names no group column")
    missing = [b for b in by if b not in df.columns]
    if missing:
        raise SlipkitError(
            f"aggregate: group column(s) {', '.join(map(repr, missing))} not in the table "
            f"(columns: {', '.join(map(str, df.columns))})"
        )
    if not (isinstance(confidence, int | float) and 0.0 < float(confidence) < 1.0):
        raise SlipkitError(f"aggregate: confidence={confidence!r} is not in (0, 1)")
    cols = _metric_columns(df, by, metrics)
    values = df[cols].astype(np.float64)
    grouped = pd.concat([df[by], values], axis=1).groupby(by, sort=False, dropna=False)
    n = grouped.size().rename("n")
    count = grouped[cols].count()
    mean = grouped[cols].mean()
    std = grouped[cols].std(ddof=1)
    k = count.to_numpy(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = stats.t.ppf(0.5 + float(confidence) / 2.0, np.where(k > 1, k - 1, np.nan))
        half = t * std.to_numpy(np.float64) / np.sqrt(k)
    ci = pd.DataFrame(half, index=std.index, columns=cols)
    parts: dict[str, pd.Series] = {"n": n}
    for c in cols:
        parts[f"{c}_mean"] = mean[c]
        parts[f"{c}_std"] = std[c]
        parts[f"{c}_ci"] = ci[c]
    # One frame built at once (one block per dtype): concatenating the Series gives a
    # block per column, and reset_index's insert into it warns of fragmentation.
    return pd.DataFrame(parts).reset_index()


__all__ = ["aggregate"]
