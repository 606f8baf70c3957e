"""The closed-loop headline plot: each detector over its debounce, false alarms beside slip."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest

from slipkit.closedloop.report import debounce_groups, headline_plot


def _summary() -> pd.DataFrame:
    rows = []
    for name, kind, k, delay, slip, fa in (
        ("svm_k1", "bundle", 1, 20.0, 2.0, 30.0),
        ("svm_k3", "bundle", 3, 60.0, 6.0, 5.0),
        ("svm_k2", "bundle", 2, 40.0, 4.0, 10.0),
        ("alignment_k1", "bundle", 1, 30.0, 3.0, 0.0),
        ("onset", "bundle", 1, 5.0, 1.0, 0.0),
        ("oracle", "oracle", math.nan, 0.5, 0.5, 0.0),
        ("none", "none", math.nan, math.nan, math.nan, 0.0),
    ):
        row = {"detector": name, "kind": kind, "debounce_k": k}
        for key, value in (
            ("delay_ms", delay),
            ("slip_mm", slip),
            ("false_alarm_pct", fa),
        ):
            row[key], row[f"{key}_std"] = value, math.nan
        row.update(p99_us=100.0, p99_budget_us=833.0)
        rows.append(row)
    return pd.DataFrame(rows)


def test_debounce_variants_form_one_curve_in_debounce_order() -> None:
    """svm_k1..k3 are one detector over its debounce; the others stand alone; bounds are out."""
    groups = debounce_groups(_summary())
    assert ["svm", "alignment", "onset"] == list(groups)
    assert ["svm_k1", "svm_k2", "svm_k3"] == groups["svm"]["detector"].tolist()
    assert [1] == groups["onset"]["debounce_k"].tolist()


def test_headline_plot_draws_slip_and_false_alarms_against_delay(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Three panels (slip / false alarms against delay, slip against compute); a PNG is written."""
    import matplotlib.pyplot as plt

    made = []
    save = plt.Figure.savefig

    def keep(fig: plt.Figure, *args: object, **kwargs: object) -> None:
        made.append([ax.get_title() for ax in fig.axes])
        save(fig, *args, **kwargs)

    monkeypatch.setattr(plt.Figure, "savefig", keep)
    path = headline_plot(_summary(), tmp_path / "h.png", title="t (1 seed)")
    assert path.is_file()
    assert [
        [
            "slip against detection delay",
            "false alarms against detection delay",
            "slip against compute per frame",
        ]
    ] == made
