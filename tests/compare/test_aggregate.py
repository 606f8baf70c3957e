"""aggregate(): per-group count, mean, std and Student-t CI half-width of each metric."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from slipkit.compare.aggregate import aggregate
from slipkit.errors import SlipkitError


def _runs() -> pd.DataFrame:
    return pd.DataFrame(
        {
            "estimator": ["svm", "svm", "svm", "mlp", "mlp"],
            "seed": [0, 1, 2, 0, 1],
            "acc": [0.8, 0.9, 1.0, 0.5, 0.7],
            "p99_us": [10.0, 12.0, 14.0, 30.0, math.nan],
            "export": ["ok"] * 5,
        }
    )


def test_columns_and_group_order() -> None:
    """Groups keep first-seen order; columns are by, n, then mean/std/ci per metric."""
    out = aggregate(_runs(), ["estimator"], ["acc", "p99_us"])
    assert ["svm", "mlp"] == out["estimator"].tolist()
    assert [
        "estimator",
        "n",
        "acc_mean",
        "acc_std",
        "acc_ci",
        "p99_us_mean",
        "p99_us_std",
        "p99_us_ci",
    ] == out.columns.tolist()
    assert [3, 2] == out["n"].tolist()


def test_mean_std_and_t_interval() -> None:
    """Mean, sample std and the t half-width match scipy's t interval of the mean."""
    out = aggregate(_runs(), ["estimator"], ["acc"], confidence=0.9).set_index(
        "estimator"
    )
    x = np.array([0.8, 0.9, 1.0])
    lo, hi = stats.t.interval(0.9, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert pytest.approx(0.9) == out.loc["svm", "acc_mean"]
    assert pytest.approx(x.std(ddof=1)) == out.loc["svm", "acc_std"]
    assert pytest.approx((hi - lo) / 2) == out.loc["svm", "acc_ci"]


def test_nan_left_out_of_that_metric_only() -> None:
    """A NaN run is dropped from its metric; one value left gives NaN std and CI."""
    out = aggregate(_runs(), ["estimator"], ["acc", "p99_us"]).set_index("estimator")
    assert 30.0 == out.loc["mlp", "p99_us_mean"]
    assert (True, True) == (
        math.isnan(out.loc["mlp", "p99_us_std"]),
        math.isnan(out.loc["mlp", "p99_us_ci"]),
    )
    assert pytest.approx(0.6) == out.loc["mlp", "acc_mean"]


def test_default_metrics_are_numeric_columns() -> None:
    """Without metrics, every numeric column not grouped on is aggregated; text is not."""
    out = aggregate(_runs(), ["estimator"])
    expected = {
        f"{m}_{s}" for m in ("seed", "acc", "p99_us") for s in ("mean", "std", "ci")
    }
    assert expected | {"estimator", "n"} == set(out.columns)


def test_boolean_metric_is_a_fraction() -> None:
    """A boolean metric's mean is the fraction of runs where it holds."""
    df = _runs().assign(within=[True, False, True, True, True])
    out = aggregate(df, ["estimator"], ["within"]).set_index("estimator")
    assert pytest.approx(2 / 3) == out.loc["svm", "within_mean"]


def test_several_group_columns() -> None:
    """Grouping on two columns gives one row per distinct pair."""
    out = aggregate(_runs(), ["estimator", "export"], ["acc"])
    assert [("svm", "ok"), ("mlp", "ok")] == list(
        zip(out["estimator"], out["export"], strict=True)
    )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"by": ["family"]}, "group column(s) 'family'"),
        ({"by": ["estimator"], "metrics": ["f1"]}, "metric 'f1' is not a column"),
        (
            {"by": ["estimator"], "metrics": ["export"]},
            "metric 'export' is not numeric",
        ),
        ({"by": ["estimator"], "confidence": 1.0}, "confidence=1.0 is not in (0, 1)"),
        ({"by": []}, "by names no group column"),
    ],
)
def test_bad_arguments_name_the_fault(kwargs: dict, message: str) -> None:
    """A missing column, a text metric or a bad confidence is a SlipkitError naming it."""
    with pytest.raises(SlipkitError) as err:
        aggregate(_runs(), **kwargs)
    assert message in str(err.value)
