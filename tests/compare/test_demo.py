"""slipkit demo: the whole pipeline, simulate -> compare -> export -> replay -> report."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.demo import (
    FAMILY_HEADERS,
    closedloop_plan,
    demo_main,
    demo_seeds,
    family_rows,
)
from slipkit.errors import SlipkitError


def _run(tmp_path: Path, overrides: list[str]) -> Path:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="demo",
            overrides=[
                "quick=true",
                "progress=false",
                f"out={tmp_path / 'demo'}",
                f"data_root={tmp_path / 'no-real-data'}",
                *overrides,
            ],
        )
        return demo_main(cfg)


def test_demo_smoke_two_families(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two families end to end: the report opens with the family table (closed-loop columns
    filled from the TacTip scenario), links each report, the best bundle is written, stage
    times and the path are printed last."""
    report = _run(
        tmp_path,
        [
            "~comparisons",
            "+comparisons={tactip: [], biotac_slip: []}",
            "quick_seeds=[0]",
            "~closedloop.families",  # the biotac scenario fills no row: its columns stay "-"
        ],
    )
    assert tmp_path / "demo" / "report.md" == report
    lines = report.read_text().splitlines()
    assert list(FAMILY_HEADERS) == [c.strip() for c in lines[2].strip("|").split("|")]
    rows = {r.split("|")[1].strip(): r.split("|") for r in lines[4:6]}
    assert {"tactip", "biotac_slip"} == set(rows)
    shown = {
        "svm_rbf": "svm_k2",
        "svm_rbf_tuned": "svm_k2",
        "svm_linear": "svm_linear_k2",
        "alignment": "alignment_k1",
    }
    verdict = rows["tactip"][2].strip()
    assert f"tactip: {shown.get(verdict, 'svm_k1')}" == rows["tactip"][8].strip()
    assert "-" != rows["tactip"][5].strip()  # slip at arrest (mm) from the closed loop
    for family in ("tactip", "biotac_slip"):
        assert f"compare/{family}/report.md" in "\n".join(lines)
        assert (tmp_path / "demo" / "compare" / family / "report.md").is_file()
        assert (tmp_path / "demo" / "exports" / family / "manifest.json").is_file()
    out = capsys.readouterr().out.strip().splitlines()
    assert str(report) == out[-1]
    assert out[-2].startswith("stage times (s): simulate ")
    # the replay stage judges each deployed bundle by the latency rule and says its word
    replayed = [line for line in out if line.startswith("replay tactip: p99 ")]
    assert 1 == len(replayed)
    assert replayed[0].rsplit(": ", 1)[-1] in {"within", "borderline", "over"}


def _fake_results() -> tuple[dict, dict, dict]:
    results = {"tactip": None, "davis": None}
    best = {
        "tactip": {
            "estimator": "svm_rbf",
            "recommended": True,
            "primary": "balanced_accuracy",
            "balanced_accuracy": 0.9,
            "balanced_accuracy_std": 0.02,
            "delay_ms": 16.7,
            "delay_ms_std": 4.0,
            "p99_us": 150.0,
            "budget_p99_us": 833.3,
        },
        "davis": {
            "estimator": "polarity_lines",
            "recommended": False,
            "why_not": "p99 1500 us > 1000 us budget",
            "primary": "f1",
            "f1": 0.5,
            "delay_ms": math.nan,
            "p99_us": 1500.0,
            "budget_p99_us": 1000.0,
        },
    }
    closed = {
        "tactip": {
            "scenario": "tactip",
            "detector": "svm_k2",
            "slip_mm": 1.25,
            "slip_mm_std": math.nan,
            "dropped_pct": 0.0,
        }
    }
    return results, best, closed


def test_family_rows_fill_closed_loop_columns_or_dash() -> None:
    """A family with a scenario shows slip and drops; one without shows '-'; p99 against the budget."""
    rows = {r[0]: r for r in family_rows(*_fake_results())}
    assert (
        "tactip",
        "svm_rbf",
        "balanced_accuracy 0.900 ± 0.020",
        "16.7 ± 4.0",
        "1.2",
        "0",
        "150.0 / 833.3 (0.18x)",
        "tactip: svm_k2",
    ) == rows["tactip"]
    assert (
        "none recommended (polarity_lines: p99 1500 us > 1000 us budget)",
        "-",
        "-",
        "-",
        "1500.0 / 1000 (1.50x)",
    ) == (
        rows["davis"][1],
        rows["davis"][3],
        rows["davis"][4],
        rows["davis"][5],
        rows["davis"][6],
    )


def test_closedloop_plan_maps_scenarios_to_compared_families() -> None:
    """Every scenario file whose family is compared runs, demo-sized; others are left out."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="demo", overrides=["quick=true"])
        plan = closedloop_plan(cfg, ["tactip", "davis"])
    assert ["davis", "tactip"] == list(plan)
    family, overrides = plan["tactip"]
    assert "tactip" == family
    assert {"closedloop=tactip", "seeds=[0]", "trials_per_speed=1"} <= set(overrides)


def test_demo_seeds_refuse_a_repeated_seed() -> None:
    """seeds=[0,0] is a one-line error naming the option."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="demo", overrides=["seeds=[0,0]"])
    with pytest.raises(SlipkitError) as err:
        demo_seeds(cfg)
    assert "seeds=[0, 0]: a seed is listed twice" == str(err.value)


@pytest.mark.slow
def test_demo_quick_end_to_end(tmp_path: Path) -> None:
    """quick=true runs every simulated family; without real data dos_real is left out."""
    report = _run(tmp_path, [])
    text = report.read_text()
    for family in (
        "tactip",
        "biotac_force",
        "biotac_slip_type",
        "fsr",
        "sliptack",
        "davis",
    ):
        assert f"compare/{family}/report.md" in text
    assert "compare/dos_real" not in text


def test_a_failing_closed_loop_scenario_costs_its_columns_not_the_demo(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A scenario whose detector cannot be exported: the demo still writes its report, the row's
    slip and drop are "-", the closed-loop cell says it failed and stderr names why."""
    import slipkit.demo

    def refuse(*args: object, **kwargs: object) -> None:
        raise SlipkitError("parity check failed for fsr_robust: no bundle written")

    monkeypatch.setattr(slipkit.demo, "_run_closedloop", refuse)
    report = _run(
        tmp_path,
        ["~comparisons", "+comparisons={tactip: []}", "quick_seeds=[0]"],
    )
    row = report.read_text().splitlines()[4].split("|")
    err = capsys.readouterr().err
    assert ("tactip", "-", "-", "tactip (failed: see the demo's stderr)") == (
        row[1].strip(),
        row[5].strip(),
        row[6].strip(),
        row[8].strip(),
    )
    assert "closed loop tactip: skipped: parity check failed for fsr_robust" in err
