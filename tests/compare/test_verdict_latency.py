"""A verdict that recommends nothing on latency names the row nearest its budget, by how
much, and what would make it fit (injected timings: no clock is read)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from slipkit.compare.report import closest_line, verdict
from slipkit.compare.table import build_table, seed_table


def _row(
    name: str, rmse: float, p99: float, back: float = math.nan, **kw: object
) -> dict:
    return {
        "estimator": name,
        "kind": "analytic",
        "class": "X",
        "rmse": rmse,
        "p50_us": p99 / 2,
        "p99_us": p99,
        "p99_unpaced_us": back,
        "budget_p99_us": 100.0,
        "export": kw.pop("export", "ok"),
        **kw,
    }


def _speed_table(back_exact: float) -> pd.DataFrame:
    """The SlipTack speed verdict's shape: every row over the 100 us budget."""
    return build_table(
        [
            _row("exact", 23.2, 300.9, back_exact),
            _row("paper_form", 93.5, 278.0, 69.1),
            _row("calibrated", 18.0, 400.9, 65.2),
            _row("spectral_gbr", 22.7, 349.7, 55.7, kind="learned"),
        ],
        "rmse",
    )


def test_closest_row_whose_graph_fits_back_to_back() -> None:
    """Nearest the budget is the lowest p99 / budget; back to back within it: the idle
    frames before each call put it over, and the gripper PC's --check decides."""
    line = closest_line(_speed_table(71.1), "rmse")
    assert line.startswith(
        "Closest to the budget: `paper_form` (rmse 93.5), p99 278.0 us = 2.78 x the "
        "100 us budget: over; frames back to back p99 69.1 us = 0.69 x the 100 us "
        "budget: within: the graph fits"
    )
    assert "`slipkit-run BUNDLE --check` on the gripper PC" in line


def test_closest_row_too_slow_back_to_back() -> None:
    """Over the budget back to back too: the graph itself is too slow, by that factor."""
    df = build_table([_row("a", 1.0, 500.0, 250.0), _row("b", 0.5, 900.0)], "rmse")
    assert closest_line(df, "rmse").endswith(
        "frames back to back still p99 250.0 us = 2.50 x the 100 us budget: over: "
        "the graph itself needs to be 2.50 x cheaper."
    )


def test_closest_row_without_back_to_back() -> None:
    """No back-to-back replay (an older table): the factor the p99 must drop by."""
    df = build_table([_row("a", 1.0, 300.0)], "rmse")
    assert closest_line(df, "rmse").endswith(
        "p99 300.0 us = 3.00 x the 100 us budget: over: it needs a p99 3.00 x lower."
    )


def test_no_closest_line_when_latency_is_not_the_reason() -> None:
    """The nearest row within its budget (kept out by something else), or nothing exported:
    no line."""
    within = build_table([_row("a", 1.0, 40.0)], "rmse")
    unexported = build_table(
        [_row("a", 1.0, math.nan, export="not exportable: no deployer")], "rmse"
    )
    assert (closest_line(within, "rmse"), closest_line(unexported, "rmse")) == ("", "")


def test_verdict_says_it_only_when_none_is_recommended() -> None:
    """The line follows a "no estimator meets the budget" verdict, not a recommendation."""
    none = "\n".join(verdict(_speed_table(71.1), "rmse"))
    fits = build_table([_row("a", 1.0, 40.0), _row("b", 0.5, 300.0, 60.0)], "rmse")
    assert (
        "Closest to the budget: `paper_form`" in none,
        "Closest" in "\n".join(verdict(fits, "rmse")),
    ) == (True, False)


def test_seed_table_pools_back_to_back_latencies() -> None:
    """Over several seeds the back-to-back p99 is that of every seed's frames pooled (as
    p99_us), not a mean of per-seed p99s; a row never replayed back to back has none."""
    per_seed = pd.concat(
        [
            build_table(
                [_row("a", 1.0, 300.0, 10.0 * (s + 1)), _row("b", 2.0, 40.0)], "rmse"
            ).assign(seed=s)
            for s in (0, 1)
        ],
        ignore_index=True,
    )
    paced = {"a": np.full(400, 300.0), "b": np.full(400, 40.0)}
    back = {"a": np.concatenate([np.full(200, 10.0), np.full(200, 50.0)])}
    df = seed_table(per_seed, paced, "rmse", unpaced=back).set_index("estimator")
    assert df.loc["a", "p99_unpaced_us"] == 50.0
    assert math.isnan(df.loc["b", "p99_unpaced_us"])
