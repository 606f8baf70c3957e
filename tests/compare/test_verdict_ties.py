"""Ties are ties: a difference within the spread over seeds is reported as a tie and broken by
delay, then false alarms, then p99; detection verdicts rank on the trial cost under limits."""

from __future__ import annotations

import math

from slipkit.compare.report import verdict
from slipkit.compare.table import build_table, choose_deploy
from slipkit.evaluate.events import Cost


def _row(name: str, cost: float, std: float, delay: float, **kw: object) -> dict:
    return {
        "estimator": name,
        "kind": "analytic",
        "class": "X",
        "cost": cost,
        "cost_std": std,
        "n_seeds": kw.pop("n_seeds", 3),
        "delay_ms": delay,
        "early_alarm_rate": kw.pop("early", 0.0),
        "false_alarms_per_min": kw.pop("fa", 1.0),
        "p50_us": 5.0,
        "p99_us": kw.pop("p99", 10.0),
        "budget_p99_us": 50.0,
        "export": "ok",
        **kw,
    }


def test_a_difference_within_the_spread_is_a_tie_broken_by_delay() -> None:
    """0.30 ± 0.05 against 0.32 ± 0.04: a tie; the later detector loses to the earlier one."""
    df = build_table([_row("a", 0.30, 0.05, 40.0), _row("b", 0.32, 0.04, 20.0)], "cost")
    choice = choose_deploy(df)
    assert ("b", ("a",), "lower delay (20 ms against 40 ms for `a`)") == (
        choice.row["estimator"],
        choice.tied,
        choice.tie_break,
    )
    text = "\n".join(verdict(df, "cost"))
    assert (
        "Tie (within the spread over 3 seeds: the difference of the means is no larger "
        "than the larger standard deviation) with `a`, broken by lower delay (20 ms "
        "against 40 ms for `a`)."
    ) in text


def test_a_difference_beyond_the_spread_is_a_win() -> None:
    """0.20 ± 0.01 against 0.32 ± 0.04: no tie, the cheaper row wins though it is later."""
    df = build_table([_row("a", 0.20, 0.01, 40.0), _row("b", 0.32, 0.04, 20.0)], "cost")
    choice = choose_deploy(df)
    assert ("a", ()) == (choice.row["estimator"], choice.tied)


def test_with_one_seed_no_tie_is_declared() -> None:
    """Without a spread (one seed) the lower cost wins outright."""
    df = build_table(
        [
            _row("a", 0.30, math.nan, 40.0, n_seeds=1),
            _row("b", 0.31, math.nan, 20.0, n_seeds=1),
        ],
        "cost",
    )
    choice = choose_deploy(df)
    assert ("a", (), "") == (choice.row["estimator"], choice.tied, choice.tie_break)


def test_equal_delays_fall_through_to_false_alarms_then_p99() -> None:
    """Same delay: fewer false alarms per minute wins; all equal but p99: the cheaper frame."""
    fa = build_table(
        [_row("a", 0.30, 0.05, 20.0, fa=3.0), _row("b", 0.31, 0.05, 20.0, fa=1.0)],
        "cost",
    )
    assert "b" == choose_deploy(fa).row["estimator"]
    p99 = build_table(
        [_row("a", 0.30, 0.05, 20.0, p99=30.0), _row("b", 0.31, 0.05, 20.0, p99=12.0)],
        "cost",
    )
    choice = choose_deploy(p99)
    assert ("b", "cheaper per frame (p99) (12 us against 30 us for `a`)") == (
        choice.row["estimator"],
        choice.tie_break,
    )


def test_the_cost_ranks_not_the_per_sample_accuracy() -> None:
    """A row with the better balanced accuracy but the higher trial cost is not chosen."""
    df = build_table(
        [
            _row("accurate", 0.60, math.nan, 30.0, n_seeds=1, balanced_accuracy=0.95),
            _row("cheap", 0.10, math.nan, 30.0, n_seeds=1, balanced_accuracy=0.70),
        ],
        "cost",
    )
    assert "cheap" == choose_deploy(df).row["estimator"]


def test_a_row_over_the_early_alarm_limit_is_passed_over() -> None:
    """Early alarms in 71 % of test trials against a 25 % limit: passed over with the rate."""
    df = build_table(
        [
            _row("window_mlp", 0.20, math.nan, 10.0, n_seeds=1, early=17 / 24),
            _row("energy", 0.30, math.nan, 30.0, n_seeds=1, early=0.125),
        ],
        "cost",
    )
    choice = choose_deploy(df, max_early_alarm_rate=0.25)
    assert (
        "energy",
        (("window_mlp", "early alarms in 71 % of test trials > 25 %"),),
    ) == (
        choice.row["estimator"],
        choice.passed_over,
    )


def test_a_row_no_cheaper_than_no_detector_is_not_recommended() -> None:
    """Ranked first on cost, a row whose cost is what never alarming costs is passed over."""
    df = build_table(
        [
            _row(
                "silent", 0.4, math.nan, math.nan, n_seeds=1, cost_without_detector=0.4
            ),
            _row("slow", 0.5, math.nan, 200.0, n_seeds=1, cost_without_detector=1.0),
        ],
        "cost",
    )
    choice = choose_deploy(df)
    assert (
        "slow",
        (
            (
                "silent",
                "costs 0.4 per trial, no less than no detector (0.4: every slip "
                "missed, no alarm)",
            ),
        ),
    ) == (choice.row["estimator"], choice.passed_over)


def test_the_report_states_the_cost_limits_and_where_points_were_chosen() -> None:
    """A detection verdict names the cost's weights, the limit and the choosing trials."""
    df = build_table(
        [
            _row(
                "a",
                0.2,
                math.nan,
                30.0,
                n_seeds=1,
                operating_point_from="validation: group k-fold by object, k=2",
            )
        ],
        "cost",
    )
    text = "\n".join(verdict(df, "cost", max_early_alarm_rate=0.25, cost=Cost()))
    assert (
        "per test trial a missed slip costs 1, an alarm before the onset (any alarm in a "
        "trial without slip) 0.2, and a detection 0.002 per ms of delay (at most a miss)"
    ) in text
    assert "early alarms in more than 25 % of the test trials" in text
    assert "`validation: group k-fold by object, k=2` (the training side only)" in text


def test_p99s_within_the_borderline_band_do_not_break_a_tie() -> None:
    """Equal on every event metric, p99 20 against 23 us: one timing; the comparison's
    order decides, whichever row timed faster in this run."""
    for p99_a, p99_b in ((20.0, 23.0), (23.0, 20.0)):
        df = build_table(
            [
                _row("fsr_onset", 0.38, 0.26, 34.7, p99=p99_a),
                _row("fsr_onset_logistic", 0.38, 0.26, 34.7, p99=p99_b),
            ],
            "cost",
        )
        choice = choose_deploy(df)
        assert (
            "fsr_onset",
            ("fsr_onset_logistic",),
            "the comparison's order (every tie-breaker equal)",
        ) == (choice.row["estimator"], choice.tied, choice.tie_break)


def test_the_verdict_holds_under_timing_noise() -> None:
    """Injected timing noise (each row's p99 drawn within +-5 % of its own, so two close
    rows' ratio moves inside the 1.25x band) never changes the verdict of three tied
    rows; a clearly slower frame still loses the tie."""
    import numpy as np

    rng = np.random.default_rng(0)
    base = {"a": 30.0, "b": 28.0, "c": 60.0}  # c is a clearly slower frame
    chosen = set()
    for _ in range(200):
        rows = [
            _row(n, 0.30 + 0.001 * i, 0.05, 20.0, p99=p * rng.uniform(0.95, 1.05))
            for i, (n, p) in enumerate(base.items())
        ]
        chosen.add(choose_deploy(build_table(rows, "cost")).row["estimator"])
    assert {"a"} == chosen


def test_p99s_within_the_seeds_spread_do_not_break_a_tie() -> None:
    """Equal trial events; p99 55 +- 23 us against 38 +- 8 us (a shared machine's draw:
    the first swung between seeds): one timing, the comparison's order decides. With a
    tight spread the same gap is a cheaper frame and wins."""
    for p99_a, p99_b in ((55.3, 38.3), (38.3, 55.3)):
        rows = [
            _row("fsr_onset", 0.38, 0.26, 34.7, p99=p99_a, p99_us_std=23.5),
            _row("fsr_onset_logistic", 0.38, 0.26, 34.7, p99=p99_b, p99_us_std=7.5),
        ]
        choice = choose_deploy(build_table(rows, "cost"))
        assert "fsr_onset" == choice.row["estimator"]
        assert "the comparison's order (every tie-breaker equal)" == choice.tie_break
    rows = [
        _row("fsr_onset", 0.38, 0.26, 34.7, p99=55.3, p99_us_std=2.0),
        _row("fsr_onset_logistic", 0.38, 0.26, 34.7, p99=38.3, p99_us_std=1.5),
    ]
    choice = choose_deploy(build_table(rows, "cost"))
    assert "fsr_onset_logistic" == choice.row["estimator"]
    assert choice.tie_break.startswith(
        "cheaper per frame (p99) (38.3 us against 55.3 us"
    )
