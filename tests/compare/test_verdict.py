"""The deploy verdict respects the p99 budget; the Pareto plot's data, units and legend."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import pandas as pd

from slipkit.compare.plots import pareto_figure, pareto_points, score_label
from slipkit.compare.report import verdict
from slipkit.compare.table import build_table, choose_deploy, metric_unit, per_unit


def _row(name: str, acc: float, p99: float, export: str = "ok", **kw: object) -> dict:
    return {
        "estimator": name,
        "kind": kw.pop("kind", "learned"),
        "class": "X",
        "balanced_accuracy": acc,
        "p50_us": p99 / 2,
        "p99_us": p99,
        "budget_p99_us": kw.pop("budget", 100.0),
        "export": export,
        **kw,
    }


def _table() -> pd.DataFrame:
    return build_table(
        [
            _row("fast", 0.80, 40.0),
            _row("slow", 0.95, 3572.4, kind="analytic"),
            _row("nobundle", 0.99, math.nan, export="not exportable: no deployer"),
        ],
        "balanced_accuracy",
    )


def test_choice_skips_over_budget_and_unexportable() -> None:
    """The higher-scoring over-budget and unexportable rows lose to the one within budget."""
    choice = choose_deploy(_table())
    assert ("fast", True) == (choice.row["estimator"], choice.recommended)
    assert (
        ("nobundle", "not exportable: no deployer"),
        ("slow", "p99 3572 us > 100 us budget: over"),
    ) == choice.passed_over


def test_verdict_names_reasons_for_passing_over() -> None:
    """The verdict recommends the within-budget row and says why each better one lost."""
    text = "\n".join(verdict(_table(), "balanced_accuracy"))
    assert "**Deploy `fast`" in text
    assert "- `slow`: p99 3572 us > 100 us budget: over" in text
    assert "- `nobundle`: not exportable: no deployer" in text
    assert "p99 40.0 us = 0.40 x the 100 us budget" in text


def test_verdict_when_none_meets_budget() -> None:
    """With every p99 over budget nothing is recommended; the best-scoring exported one is named."""
    df = build_table(
        [_row("calibrated", 0.9, 3572.4), _row("other", 0.5, 200.0)],
        "balanced_accuracy",
    )
    choice = choose_deploy(df)
    assert ("calibrated", False) == (choice.row["estimator"], choice.recommended)
    first = verdict(df, "balanced_accuracy")[0]
    assert first.startswith("**No estimator meets the budget.**")
    assert "`calibrated`" in first
    assert "p99 3572.4 us = 35.72 x the 100 us budget" in first
    assert "Deploy" not in first


def test_borderline_margin_is_flagged() -> None:
    """A p99 just under the budget is chosen but its line says it is borderline."""
    df = build_table([_row("edge", 0.9, 48.0, budget=50.0)], "balanced_accuracy")
    first = verdict(df, "balanced_accuracy")[0]
    assert "p99 48.0 us = 0.96 x the 50 us budget (borderline" in first


def test_far_over_budget_is_not_borderline() -> None:
    """A p99 many times the budget is plainly over it, not a borderline case."""
    df = build_table([_row("far", 0.9, 3572.4)], "balanced_accuracy")
    assert "borderline" not in verdict(df, "balanced_accuracy")[0]


def test_slightly_over_budget_is_borderline_and_recommended_flagged() -> None:
    """A p99 of 60.6 us against 50 us (1.21 x, inside the latency rule's margin) is
    recommended, flagged borderline; 63 us (1.26 x) is over and passed over."""
    df = build_table([_row("fsr", 0.9, 60.6, budget=50.0)], "balanced_accuracy")
    choice = choose_deploy(df)
    first = verdict(df, "balanced_accuracy")[0]
    assert (True, True) == (choice.recommended, choice.borderline)
    assert "p99 60.6 us = 1.21 x the 50 us budget (borderline" in first
    over = choose_deploy(
        build_table([_row("fsr", 0.9, 63.0, budget=50.0)], "balanced_accuracy")
    )
    assert (False, False) == (over.recommended, over.borderline)


def test_pareto_plot_uses_p99() -> None:
    """The Pareto points sit at each estimator's p99, not its p50."""
    pts = pareto_points(_table())
    assert {"fast": 40.0, "slow": 3572.4} == dict(
        zip(pts["estimator"], pts["x_us"], strict=True)
    )


def test_pareto_labels_of_neighbours_are_staggered() -> None:
    """Two estimators at nearly the same point get different label offsets."""
    df = build_table(
        [_row("mlp1", 0.90, 16.0), _row("mlp3", 0.901, 16.2)], "balanced_accuracy"
    )
    pts = pareto_points(df)
    assert 2 == len(set(zip(pts["dx"], pts["dy"], strict=True)))


def test_pareto_legend_only_for_drawn_kinds() -> None:
    """A table of learned rows only has no 'analytic' legend entry; the x axis says p99 (us)."""
    df = build_table([_row("a", 0.8, 10.0), _row("b", 0.9, 20.0)], "balanced_accuracy")
    fig = pareto_figure(df, "balanced_accuracy", "t")
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    xlabel = ax.get_xlabel()
    plt.close(fig)
    assert ["learned", "Pareto front", "p99 budget"] == labels
    assert "p99 (us" in xlabel


def test_units_are_composed_unambiguously() -> None:
    """A compound denominator is parenthesised; regression scores carry their unit."""
    assert "us/N" == per_unit("us", "N")
    assert "us/(mm/s)" == per_unit("us", "mm/s")
    assert "1/(N/mm)" == per_unit("1", "N/mm")
    assert "mm/s" == metric_unit("rmse", ["rmse", "rmse_speed"])
    assert "score = -rmse (N), higher is better" == score_label(
        "rmse", ["rmse_x", "rmse_y", "rmse_z"]
    )
