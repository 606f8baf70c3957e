"""A detection comparison's verdict can limit alarms per disturbance (issue 14): a row above
``verdict.max_alarms_per_disturbance`` is passed over with its rate, as an over-budget row is."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from slipkit.compare.report import verdict
from slipkit.compare.table import build_table, choose_deploy, verdict_limits
from slipkit.errors import SlipkitError


def _row(name: str, acc: float, alarms: float, **kw: object) -> dict[str, object]:
    return {
        "estimator": name,
        "kind": kw.pop("kind", "analytic"),
        "class": "X",
        "balanced_accuracy": acc,
        "p50_us": 5.0,
        "p99_us": kw.pop("p99", 10.0),
        "budget_p99_us": 50.0,
        "export": kw.pop("export", "ok"),
        "disturbances": 13,
        "alarms_per_disturbance": alarms,
        "delay_ms": 30.0,
        **kw,
    }


def _fsr_like() -> pd.DataFrame:
    return build_table(
        [
            _row("window_logreg", 0.77, 7 / 13, kind="learned"),
            _row("fsr_paper", 0.70, 6 / 13),
            _row("fsr_robust", 0.65, 0.0),
        ],
        "balanced_accuracy",
    )


def test_a_row_firing_on_more_disturbances_than_the_limit_is_passed_over() -> None:
    """Limit 10 %: the two knock-prone rows are passed over with their rates, robust chosen."""
    choice = choose_deploy(_fsr_like(), max_alarms_per_disturbance=0.10)
    assert ("fsr_robust", True) == (choice.row["estimator"], choice.recommended)
    assert (
        ("window_logreg", "fires on 54 % of disturbances > 10 %"),
        ("fsr_paper", "fires on 46 % of disturbances > 10 %"),
    ) == choice.passed_over


def test_the_disturbance_rate_is_named_before_a_noisy_p99() -> None:
    """A knock-prone row that is also over budget is passed over for its rate (stable)."""
    df = build_table(
        [_row("a", 0.9, 0.5, p99=80.0), _row("b", 0.8, 0.0)], "balanced_accuracy"
    )
    choice = choose_deploy(df, max_alarms_per_disturbance=0.1)
    assert (("a", "fires on 50 % of disturbances > 10 %"),) == choice.passed_over


def test_an_unexported_row_is_named_as_such_before_its_rate() -> None:
    """Not exported comes first: there is no bundle to deploy whatever the rate."""
    df = build_table(
        [_row("a", 0.9, 0.5, export="not exportable: x"), _row("b", 0.8, 0.0)],
        "balanced_accuracy",
    )
    choice = choose_deploy(df, max_alarms_per_disturbance=0.1)
    assert (("a", "not exportable: x"),) == choice.passed_over


def test_without_a_limit_the_rule_is_unchanged() -> None:
    """choose_deploy(df) keeps ranking by score alone (backward compatible)."""
    assert "window_logreg" == choose_deploy(_fsr_like()).row["estimator"]


def test_a_row_without_disturbances_is_not_held_to_the_limit() -> None:
    """NaN alarms per disturbance (the data marks none): the limit does not apply."""
    df = build_table([_row("a", 0.9, math.nan)], "balanced_accuracy")
    assert "a" == choose_deploy(df, max_alarms_per_disturbance=0.1).row["estimator"]


def test_a_rate_at_the_limit_passes() -> None:
    """The limit is inclusive: 10 % fired with a 10 % limit is within it."""
    df = build_table([_row("a", 0.9, 0.10)], "balanced_accuracy")
    assert True is choose_deploy(df, max_alarms_per_disturbance=0.10).recommended


def test_no_row_within_the_limit_is_shown_not_recommended() -> None:
    """Every row above the limit: the best exported one, not recommended, says so."""
    df = build_table([_row("a", 0.9, 0.5), _row("b", 0.8, 0.3)], "balanced_accuracy")
    choice = choose_deploy(df, max_alarms_per_disturbance=0.1)
    assert ("a", False) == (choice.row["estimator"], choice.recommended)
    text = "\n".join(verdict(df, "balanced_accuracy", max_alarms_per_disturbance=0.1))
    assert "**No estimator meets the budget and the disturbance limit.**" in text


def test_the_report_verdict_prints_the_rate_and_the_limit() -> None:
    """The verdict line states the chosen row's rate of how many disturbances and the limit."""
    lines = verdict(_fsr_like(), "balanced_accuracy", max_alarms_per_disturbance=0.10)
    assert lines[0].startswith("**Deploy `fsr_robust`")
    assert ", fires on 0 % of 13 disturbances (limit 10 %)." in lines[0]
    assert "- `window_logreg`: fires on 54 % of disturbances > 10 %" in lines


@pytest.mark.parametrize(
    ("node", "match"),
    [
        ({"max_alarms_per_disturbance": 10}, r"verdict\.max_alarms_per_disturbance"),
        ({"max_alarms_per_disturbance": "low"}, r"fraction in \[0, 1\]"),
        ({"max_alarm_per_disturbance": 0.1}, r"verdict\.max_alarm_per_disturbance"),
        (0.1, "must be a mapping"),
    ],
)
def test_bad_verdict_limits_are_named(node: object, match: str) -> None:
    """A limit outside [0, 1], not a number, an unknown key or no mapping: SlipkitError."""
    with pytest.raises(SlipkitError, match=match):
        verdict_limits(node)  # type: ignore[arg-type]


def test_verdict_limits_read_the_fsr_comparison() -> None:
    """configs/comparison/fsr.yaml sets the 10 % disturbance limit beside the 25 % early-alarm one."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from slipkit import config_dir

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="compare", overrides=["comparison=fsr"])
    node = OmegaConf.to_container(cfg.comparison, resolve=True)
    assert {
        "max_alarms_per_disturbance": 0.10,
        "max_early_alarm_rate": 0.25,
    } == verdict_limits(node["verdict"])  # type: ignore[index,call-overload]
