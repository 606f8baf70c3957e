"""aggregate(): per-group count, mean, std and Student-t CI half-width of each metric."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from slipkit.compare.report import cell, verdict
from slipkit.compare.table import block_p99, choose_deploy, seed_table
from slipkit.errors import SlipkitError
from slipkit.evaluate.aggregate import aggregate


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


def test_block_p99_ignores_a_stall_in_one_block() -> None:
    """A burst of slow decisions inside one of five blocks leaves the checked p99 unchanged."""
    base = np.tile(np.arange(1.0, 101.0), 20)  # 2000 decisions, every block alike
    stalled = base.copy()
    stalled[100:160] = 5000.0  # a 60-decision stall in the first block
    assert block_p99(base) == block_p99(stalled)


def test_block_p99_of_few_decisions_is_the_plain_p99() -> None:
    """With fewer decisions than two per block, the plain p99 is returned."""
    lat = np.arange(1.0, 8.0)
    assert np.percentile(lat, 99) == block_p99(lat)


def _seed_rows() -> pd.DataFrame:
    rows = []
    for seed, (a, b) in enumerate([(0.90, 0.80), (0.80, 0.82), (0.85, 0.84)]):
        for est, acc, p99, export in (("a", a, 60.0, "ok"), ("b", b, 20.0, "ok")):
            rows.append(
                {
                    "estimator": est,
                    "kind": "learned",
                    "class": "X",
                    "balanced_accuracy": acc,
                    "p50_us": p99 / 2,
                    "p99_us": p99,
                    "budget_p99_us": 50.0,
                    "export": export,
                    "seed": seed,
                }
            )
    return pd.DataFrame(rows)


def test_seed_table_averages_and_keeps_the_spread() -> None:
    """One row per estimator: the mean primary as its score, the std beside it, n_seeds."""
    lat = {"a": np.full(100, 40.0), "b": np.full(100, 20.0)}
    df = seed_table(_seed_rows(), lat, "balanced_accuracy").set_index("estimator")
    assert pytest.approx([0.85, 0.82]) == df["score"].tolist()
    assert pytest.approx(0.05) == df.loc["a", "balanced_accuracy_std"]
    assert [3, 3] == df["n_seeds"].tolist()


def test_seed_table_checks_the_budget_on_pooled_latencies() -> None:
    """The pooled block p99 is checked, not the per-seed p99s: 'a' (60 us each) meets 50 us on
    40 us, so it stays deployable and ties with 'b' (0.85 ± 0.05 against 0.82 ± 0.02)."""
    lat = {"a": np.full(100, 40.0), "b": np.full(100, 20.0)}
    df = seed_table(_seed_rows(), lat, "balanced_accuracy")
    choice = choose_deploy(df)
    assert ("b", ("a",), 40.0) == (
        choice.row["estimator"],
        choice.tied,
        df.set_index("estimator").loc["a", "p99_us"],
    )
    assert (True, True) == tuple(df["within_budget"])


def test_seed_table_export_fails_if_any_seed_failed() -> None:
    """An estimator whose bundle failed on one seed is reported with that seed's reason."""
    rows = _seed_rows()
    rows.loc[(rows["estimator"] == "a") & (rows["seed"] == 1), "export"] = (
        "not exportable: x"
    )
    df = seed_table(rows, {"b": np.full(10, 20.0)}, "balanced_accuracy")
    assert ["not exportable: x", "ok"] == df["export"].tolist()


def test_report_cells_show_the_spread_of_scores_not_of_latencies() -> None:
    """A seeded table prints accuracy as mean ± std; the pooled p99 and the budget bare."""
    lat = {"a": np.full(100, 40.0), "b": np.full(100, 20.0)}
    row = seed_table(_seed_rows(), lat, "balanced_accuracy").iloc[0]
    assert ("0.850 ± 0.050", "40.0", "50") == (
        cell(row, "balanced_accuracy", "{:.3f}"),
        cell(row, "p99_us", "{:.1f}"),
        cell(row, "budget_p99_us", "{:.4g}"),
    )


def test_over_budget_row_under_load_is_told_apart() -> None:
    """A row over budget whose quietest block meets it is passed over with a load note."""
    loaded = np.tile(
        np.r_[np.full(95, 30.0), np.full(5, 900.0)], 20
    )  # over in every block
    loaded[:400] = 30.0  # the first of the five blocks is quiet
    lat = {"a": loaded, "b": np.full(100, 20.0)}
    df = seed_table(_seed_rows(), lat, "balanced_accuracy")
    lines = verdict(df, "balanced_accuracy")
    assert (30.0, 900.0) == tuple(
        df.set_index("estimator").loc["a", ["p99_quiet_us", "p99_us"]]
    )
    assert (
        "- `a`: p99 900 us > 50 us budget: over (its quietest block's p99 30.0 us meets the "
        "budget: the machine's load put it over; re-measure on an idle machine)"
    ) in lines


def test_seed_table_keeps_where_each_operating_point_was_chosen() -> None:
    """A text column (operating_point_from) survives the averaging, each value once."""
    rows = _seed_rows().assign(
        operating_point_from="validation: group k-fold by trial, k=3"
    )
    df = seed_table(rows, {}, "balanced_accuracy").set_index("estimator")
    assert ["validation: group k-fold by trial, k=3"] * 2 == df[
        "operating_point_from"
    ].tolist()
