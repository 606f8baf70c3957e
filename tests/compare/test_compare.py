"""slipkit compare: the unified table, the Pareto front, unexportable rows and the report files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given
from hypothesis import strategies as st

from slipkit import config_dir
from slipkit.compare.adapters import ROW_COLUMNS, binary_rates
from slipkit.compare.commands import compare_main
from slipkit.compare.table import COLUMNS, best_row, build_table, pareto_front, score_of

PNGS = {"pareto.png", "roc.png", "latency.png", "confusion.png"}


def _compose(overrides: list[str]):  # type: ignore[no-untyped-def]
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name="compare", overrides=[*overrides, "progress=false"])


def test_pareto_front_hand_made_case() -> None:
    """Points beaten on both cost and score are off the front; ties and NaN are handled."""
    cost = [1.0, 2.0, 3.0, 2.5, 4.0, math.nan, 1.0]
    score = [0.5, 0.8, 0.9, 0.7, 0.9, 1.0, 0.4]
    expected = np.array([True, True, True, False, False, False, False])
    assert expected.tolist() == pareto_front(cost, score).tolist()


@given(
    st.lists(
        st.tuples(
            st.floats(0.1, 1e4, allow_nan=False), st.floats(-1, 1, allow_nan=False)
        ),
        min_size=1,
        max_size=12,
    )
)
def test_pareto_front_points_are_not_dominated(
    points: list[tuple[float, float]],
) -> None:
    """No front point is dominated, every other point is, and the best score is always on it."""
    c = np.array([p[0] for p in points])
    s = np.array([p[1] for p in points])
    front = pareto_front(c, s)
    for i in range(len(c)):
        dominated = any(
            c[j] <= c[i] and s[j] >= s[i] and (c[j] < c[i] or s[j] > s[i])
            for j in range(len(c))
            if j != i
        )
        assert (not dominated) == bool(front[i])
    assert True == bool(front[s == s.max()].any())  # noqa: E712 - expected == actual


def test_binary_rates_of_a_confusion_matrix() -> None:
    """TPR, TNR, F1 and balanced accuracy come from [[tn, fp], [fn, tp]] with slip second."""
    r = binary_rates(np.array([[90, 10], [5, 15]]))
    assert 0.75 == pytest.approx(r["tpr"])
    assert 0.9 == pytest.approx(r["tnr"])
    assert 0.1 == pytest.approx(r["fpr"])
    assert 0.825 == pytest.approx(r["balanced_accuracy"])
    assert 30 / 45 == pytest.approx(r["f1"])


def test_lower_is_better_primaries_are_negated() -> None:
    """RMSE-like primaries become negative scores so the Pareto front still maximises."""
    assert -0.3 == score_of({"rmse": 0.3}, "rmse")
    assert 0.9 == score_of({"accuracy": 0.9}, "accuracy")


def test_best_row_prefers_exported_within_budget() -> None:
    """A higher score that cannot be deployed loses to the best deployable row."""
    rows = [
        {
            "estimator": "a",
            "accuracy": 0.99,
            "p50_us": math.nan,
            "export": "not exportable: x",
        },
        {
            "estimator": "b",
            "accuracy": 0.90,
            "p50_us": 5.0,
            "export": "ok",
            "within_budget": True,
        },
        {
            "estimator": "c",
            "accuracy": 0.95,
            "p50_us": 50.0,
            "export": "ok",
            "within_budget": False,
        },
    ]
    df = build_table(rows, "accuracy")
    best = best_row(df)
    assert best is not None
    assert "b" == best["estimator"]


def test_classification_comparison_writes_report(tmp_path: Path) -> None:
    """A tiny TacTip comparison: one row per estimator, unified columns, identical split, PNGs."""
    out = tmp_path / "tactip"
    cfg = _compose(
        [
            "comparison=tactip",
            "comparison.dataset.n_trials=6",
            "comparison.task_overrides.svm_rbf_tuned.search.n_trials=3",
            f"out={out}",
            "cost.max_frames=100",
            "cost.warmup=2",
        ]
    )
    report = compare_main(cfg)
    assert out / "report.md" == report
    df = pd.read_csv(out / "metrics.csv")
    assert [
        "svm_rbf",
        "svm_rbf_tuned",
        "svm_linear",
        "alignment",
        "alignment_fast",
    ] == df["estimator"].tolist()
    assert set(COLUMNS) <= set(df.columns)
    assert set(ROW_COLUMNS) <= set(df.columns)
    assert ["ok"] * 5 == df["export"].tolist()
    # CV fits count: the search's (3 candidates x 3 folds), or the 3-fold validation of
    # the untuned rows (the run's objective), then the final fit, then the 3 folds whose
    # out-of-fold decisions choose the debounce (the operating point).
    assert [3 + 1 + 3, 3 * 3 + 1 + 3, 3 + 1 + 3] == df["fit_calls"].tolist()[:3]
    assert True == bool(np.isfinite(df["p99_us"]).all())  # noqa: E712
    assert PNGS | {"search_trials.png"} <= {p.name for p in out.glob("*.png")}
    text = report.read_text()
    assert "slipkit compare" in text
    assert "identical split" in text
    for png in PNGS:
        assert f"]({png})" in text


def test_detector_comparison_exports_every_row(tmp_path: Path) -> None:
    """A tiny DAVIS comparison: the polarity rules, the onset rule and the learned classifier
    all export."""
    out = tmp_path / "davis"
    cfg = _compose(["comparison=davis", "comparison.dataset.n_trials=4", f"out={out}"])
    compare_main(cfg)
    df = pd.read_csv(out / "metrics.csv")
    assert ["polarity_lines", "polarity_square", "onset", "event_logreg"] == df[
        "estimator"
    ].tolist()
    assert ["analytic", "analytic", "analytic", "learned"] == df["kind"].tolist()
    assert [True] * 4 == (df["export"] == "ok").tolist()
    assert True == bool(np.isfinite(df["f1"]).all())  # noqa: E712
    assert True == bool(np.isfinite(df["p99_us"]).all())  # noqa: E712
    # each row's debounce chosen on its training trials from the task's candidates
    assert set(df["debounce_k"]) <= {1, 2, 3}
    assert True == bool(  # noqa: E712
        df["operating_point_from"].str.contains("training trials").all()
    )
    assert (out / "delays.png").is_file()


def test_stream_detector_comparison_exports(tmp_path: Path) -> None:
    """A tiny FSR comparison: every calibrated detector is exported and timed against the budget."""
    out = tmp_path / "fsr"
    cfg = _compose(
        [
            "comparison=fsr",
            "scene@comparison.scene=fsr_probe_slide",  # one wiring: every detector exports
            "comparison.dataset.n_trials=2",
            f"out={out}",
            "cost.max_frames=200",
        ]
    )
    compare_main(cfg)
    df = pd.read_csv(out / "metrics.csv")
    assert 6 == len(df)
    assert ["ok"] * 6 == df["export"].tolist()
    assert [50.0] * 6 == df["budget_p99_us"].round(6).tolist()
    assert True == bool(np.isfinite(df["roc_auc"]).all())  # noqa: E712
    assert {"roc.png", "latency.png", "delays.png", "pareto.png"} <= {
        p.name for p in out.glob("*.png")
    }


def test_fit_timer_times_clones_and_restores_the_class() -> None:
    """Every fit of the class is timed while patched; afterwards the class is as before."""
    from sklearn.base import clone
    from sklearn.dummy import DummyClassifier

    from slipkit.compare.costs import FitTimer

    timer = FitTimer()
    X, y = np.zeros((4, 1)), np.array([0, 1, 0, 1])
    before = DummyClassifier.__dict__["fit"]
    with timer.patch(DummyClassifier):
        model = DummyClassifier()
        model.fit(X, y)
        clone(model).fit(X, y)
    assert 2 == len(timer.calls)
    assert before is DummyClassifier.__dict__["fit"]
    assert True == (timer.total_s >= 0)  # noqa: E712
