"""Plot hygiene: every numeric axis carries its unit, legends list only what is drawn."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from slipkit.compare import plots
from slipkit.compare.adapters import Evaluation
from slipkit.compare.costs import DeployCost
from slipkit.compare.table import block_p99, build_table

#: axes whose ticks are names, not numbers: no unit to carry
CATEGORICAL = {"estimator", "true class", "predicted class"}
UNIT = re.compile(r"\([^)]*\)")


def _evals() -> dict[str, Evaluation]:
    roc = {"fpr": np.linspace(0, 1, 5), "tpr": np.linspace(0, 1, 5) ** 0.5}
    return {
        name: Evaluation(
            confusion=(["static", "slip"], np.array([[50, 2], [3, 9]])),
            roc={**roc, "auc": 0.8, "unit": "frame", "point": (0.1, 0.6)},
            delays_ms=[10.0, 20.0, 30.0],
            vs_time=pd.DataFrame(
                {"t_rel_s": [-0.1, 0.0, 0.1], "accuracy": [0.5, 0.7, 0.9]}
            ),
            vs_width=pd.DataFrame({"ms": [10, 25, 50], "accuracy": [0.6, 0.7, 0.8]}),
            search=pd.DataFrame({"number": [0, 1, 2], "value": [0.6, 0.8, 0.7]}),
        )
        for name in ("mlp1", "mlp3")
    }


def _costs() -> dict[str, DeployCost]:
    rng = np.random.default_rng(0)
    out = {}
    for name, scale in (("mlp1", 20.0), ("mlp3", 30.0)):
        lat = rng.gamma(4.0, scale / 4.0, 500)
        lat[10] = 40000.0  # one stall
        out[name] = DeployCost(
            True,
            "ok",
            latency_us=lat,
            p50_us=float(np.median(lat)),
            p99_us=block_p99(lat),
            budget_p99_us=50.0,
        )
    return out


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Each figure a plot function would save, kept open for inspection."""
    made: list[Any] = []

    def keep(fig: Any, path: Path) -> Path:
        made.append(fig)
        return path

    monkeypatch.setattr(plots, "_save", keep)
    yield made
    for fig in made:
        plt.close(fig)


def _table() -> pd.DataFrame:
    rows = [
        {"estimator": e, "kind": k, "class": "X", "rmse": r, "rmse_x": r, "p99_us": p}
        for e, k, r, p in (
            ("mlp1", "learned", 1.0, 16.0),
            ("normals", "analytic", 2.0, 3.0),
        )
    ]
    df = build_table(rows, "rmse")
    df["budget_p99_us"] = 50.0
    df["export"] = "ok"
    return df


def test_every_numeric_axis_names_its_unit(figures: list[Any], tmp_path: Path) -> None:
    """Each plot's x and y labels carry a unit in parentheses, except name axes."""
    evals, costs = _evals(), _costs()
    plots.plot_pareto(_table(), "rmse", "t", tmp_path / "p.png")
    plots.plot_curves(evals, "vs_time", tmp_path / "t.png")
    plots.plot_curves(evals, "vs_width", tmp_path / "w.png")
    plots.plot_roc(evals, tmp_path / "r.png")
    plots.plot_delays(evals, tmp_path / "d.png")
    plots.plot_latency(costs, tmp_path / "l.png")
    plots.plot_search(evals, tmp_path / "s.png")
    plots.plot_confusions(evals, tmp_path / "c.png")
    labels = {
        label
        for fig in figures
        for ax in fig.axes
        for label in (ax.get_xlabel(), ax.get_ylabel())
        if label and label not in CATEGORICAL
    }
    unlabelled = [
        i
        for i, fig in enumerate(figures)
        if not any(ax.get_xlabel() for ax in fig.axes)
        or not any(ax.get_ylabel() for ax in fig.axes)
    ]
    assert 8 == len(figures)
    assert [] == unlabelled
    assert set() == {label for label in labels if not UNIT.search(label)}
    assert "score = -rmse (N), higher is better" in labels


@pytest.mark.parametrize(
    ("kinds", "expected"),
    [
        (
            ("learned", "analytic"),
            ["analytic", "learned", "Pareto front", "p99 budget"],
        ),
        (("analytic", "analytic"), ["analytic", "Pareto front", "p99 budget"]),
    ],
)
def test_pareto_legend_lists_the_kinds_drawn(
    kinds: tuple[str, str], expected: list[str]
) -> None:
    """The legend has one entry per kind present, the front and the budget line."""
    df = _table().assign(kind=list(kinds))
    fig = plots.pareto_figure(df, "rmse", "t")
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    plt.close(fig)
    assert expected == labels


def test_pareto_marks_passed_over_estimators_and_says_how_many_seeds() -> None:
    """An over-budget row is drawn hollow grey with its own legend entry; the title counts seeds."""
    df = _table()
    df.loc[df["estimator"] == "mlp1", "p99_us"] = 500.0  # 10x the 50 us budget
    df["n_seeds"] = 3
    pts = plots.pareto_points(df)
    assert ["p99" in w for w in pts["passed_over"]] == [
        e == "mlp1" for e in pts["estimator"]
    ]
    fig = plots.pareto_figure(df, "rmse", "t")
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    hollow = [
        c for c in ax.collections if c.get_label() == "passed over by the verdict"
    ]
    title = ax.get_title()
    plt.close(fig)
    assert "passed over by the verdict" in labels
    assert "learned" not in labels
    assert 1 == len(hollow)
    assert 0 == len(hollow[0].get_facecolors())
    assert "t (3 seeds, mean)" == title


def test_per_seed_plots_say_which_seed(figures: list[Any], tmp_path: Path) -> None:
    """ROC, confusion, delays and curves name the seed they show."""
    evals = _evals()
    plots.plot_roc(evals, tmp_path / "r.png", seed=2)
    plots.plot_confusions(evals, tmp_path / "c.png", seed=2)
    plots.plot_delays(evals, tmp_path / "d.png")
    plots.plot_curves(evals, "vs_time", tmp_path / "t.png", seed=2)
    titles = [
        fig.get_suptitle() + " ".join(ax.get_title() for ax in fig.axes)
        for fig in figures
    ]
    assert ["seed 2" in t for t in titles] == [True, True, False, True]
    assert "first seed's run" in titles[2]
    roc_legend = [t.get_text() for t in figures[0].axes[0].get_legend().get_texts()]
    assert [t.split(" (")[0] for t in roc_legend] == ["mlp1", "mlp3"]


def test_latency_budget_line_faces_the_checked_p99(
    figures: list[Any], tmp_path: Path
) -> None:
    """Each latency panel draws the budget and the block p99 it is checked on; a stall is counted, not drawn off-axis."""
    costs = _costs()
    plots.plot_latency(costs, tmp_path / "l.png")
    (fig,) = figures
    for ax, c in zip(fig.axes, costs.values(), strict=True):
        lines = {ln.get_label(): ln.get_xdata()[0] for ln in ax.get_lines()}
        assert {
            "p99 budget 50 us": 50.0,
            f"p99 {c.p99_us:.1f} us (checked)": c.p99_us,
        } == lines
        assert "1 above" in ax.get_title()
        assert "decisions (count)" == ax.get_ylabel()
    hi = 1.5 * max(50.0, *(c.p99_us for c in costs.values()))
    assert pytest.approx((0.0, hi)) == fig.axes[-1].get_xlim()
