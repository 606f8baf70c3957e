"""slipkit demo: the whole pipeline, simulate -> compare -> export -> replay -> report."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.demo import (
    FAMILY_HEADERS,
    closedloop_pick,
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
        "svm_rbf_tuned": "svm_tuned_k2",
        "svm_linear": "svm_linear_k2",
        "alignment": "alignment_k1",
        "alignment_fast": "alignment_fast_k1",
    }
    verdict = rows["tactip"][2].strip()
    if (
        verdict in shown
    ):  # the verdict's own detector, its slip at arrest beside its score
        assert f"closed loop tactip: {shown[verdict]}" == rows["tactip"][9].strip()
        assert "-" != rows["tactip"][6].strip()
    else:  # no verdict recommended: no closed loop, the note says why
        assert verdict.startswith("none (best: ")
        assert ("-", "-") == (rows["tactip"][6].strip(), rows["tactip"][7].strip())
    for family in ("tactip", "biotac_slip"):
        assert f"compare/{family}/report.md" in "\n".join(lines)
        assert (tmp_path / "demo" / "compare" / family / "report.md").is_file()
        exports = tmp_path / "demo" / "exports"
        recommended = not rows[family][2].strip().startswith("none (best: ")
        shown = exports / "not_recommended" / family
        bundle, other = (
            (exports / family, shown) if recommended else (shown, exports / family)
        )
        assert (bundle / "manifest.json").is_file()
        assert not other.exists()
    out = capsys.readouterr().out.strip().splitlines()
    assert str(report) == out[-1]
    assert out[-2].startswith("stage times (s): simulate ")
    # the replay stage judges each deployed bundle by the latency rule and says its word
    replayed = [line for line in out if line.startswith("replay tactip: p99 ")]
    assert 1 == len(replayed)
    assert replayed[0].rsplit(": ", 1)[-1] in {"within", "borderline", "over"}


def _fake_results() -> tuple[dict, dict, dict]:
    results = {"tactip": None, "davis": None, "sliptack": None, "biotac_force": None}
    best = {
        "tactip": {
            "estimator": "svm_rbf",
            "recommended": True,
            "primary": "cost",
            "cost": 0.12,
            "cost_std": 0.03,
            "detected_rate": 0.97,
            "detected_rate_std": 0.03,
            "early_alarm_rate": 0.1,
            "early_alarm_rate_std": math.nan,
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
        "sliptack": {
            "estimator": "spectral_gbr",
            "recommended": True,
            "primary": "rmse",
            "rmse": 20.5,
            "rmse_std": 1.5,
            "rmse_speed": 20.5,
            "p99_us": 90.0,
            "budget_p99_us": 100.0,
        },
        "biotac_force": {
            "estimator": "lwr",
            "recommended": True,
            "primary": "rmse",
            "rmse": 0.25,
            "rmse_x": 0.2,
            "false_alarms_per_min": 1.5,
            "p99_us": 10.0,
            "budget_p99_us": 3333.0,
        },
    }
    closed = {
        "tactip": {
            "scenario": "tactip",
            "ran": True,
            "detector": "svm_k2",
            "slip_mm": 1.25,
            "slip_mm_std": math.nan,
            "dropped_pct": 0.0,
        },
        # a scenario that ran another detector than the verdict's must never fill the row
        "davis": {
            "scenario": "davis",
            "ran": True,
            "detector": "polarity_lines",
            "slip_mm": 3.0,
            "dropped_pct": 10.0,
        },
        "sliptack": {
            "scenario": "sliptack",
            "why": "no closed loop: spectral_gbr decides no slip in a grasp",
        },
    }
    return results, best, closed


def test_family_rows_show_the_verdicts_own_closed_loop_or_dash_with_a_reason() -> None:
    """Verdict X -> the closed loop of X, else '-' and why; one unit per detection cell;
    p99 against the budget with the latency rule's word."""
    rows = {r[0]: r for r in family_rows(*_fake_results())}
    assert len(FAMILY_HEADERS) == len(rows["tactip"])
    assert (
        "tactip",
        "svm_rbf",
        "cost 0.120 ± 0.030 (detected 97 ± 3 %)",
        "early in 10 % of trials",
        "16.7 ± 4.0",
        "1.2",
        "0",
        "150.0 / 833.3 (0.18x)",
        "closed loop tactip: svm_k2",
    ) == rows["tactip"]
    # not recommended: the best-scoring one's numbers, no closed loop, the reason
    assert (
        "none (best: polarity_lines)",
        "F1 0.500",
        "-",
        "-",
        "-",
        "1500.0 / 1000 (1.50x, over)",
        "polarity_lines: p99 1500 us > 1000 us budget",
    ) == (rows["davis"][1], *rows["davis"][2:3], *rows["davis"][4:])
    assert (
        "RMSE 20.5 ± 1.5 mm/s",
        "-",
        "-",
        "90.0 / 100 (0.90x, borderline)",
        "no closed loop: spectral_gbr decides no slip in a grasp",
    ) == (rows["sliptack"][2], *rows["sliptack"][5:])
    assert (
        "RMSE 0.250 N",
        "1.5 /min",
        "-",
        "no closed-loop scenario",
    ) == (*rows["biotac_force"][2:4], rows["biotac_force"][6], rows["biotac_force"][8])


def test_closedloop_pick_never_falls_back_to_another_detector() -> None:
    """The mapped detector, else the one named as the verdict, else none and why."""
    names = ["svm_k1", "svm_k2", "alignment_k1"]
    shown = {"svm_rbf": "svm_k2"}
    assert ("svm_k2", "") == closedloop_pick("tactip", "svm_rbf", True, names, shown)
    assert ("svm_k1", "") == closedloop_pick("tactip", "svm_k1", True, names, {})
    pick, why = closedloop_pick("tactip", "svm_linear", True, names, shown)
    assert (None, "no closed loop: svm_linear decides no slip in a grasp") == (
        pick,
        why,
    )
    assert (None, "no closed loop: no detector recommended") == closedloop_pick(
        "tactip", "svm_rbf", False, names, shown
    )
    with pytest.raises(
        SlipkitError, match=r"closedloop.detector.tactip.svm_rbf=svm_k9"
    ):
        closedloop_pick("tactip", "svm_rbf", True, names, {"svm_rbf": "svm_k9"})


def test_every_compared_estimator_has_its_closed_loop_detector() -> None:
    """Each estimator of a family with a closed-loop scenario decides slip there as itself."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="demo")
        plan = closedloop_plan(cfg, [str(f) for f in cfg.comparisons])
        assert {"tactip", "biotac", "fsr", "sliptack", "davis"} <= set(plan)
        for name, (family, overrides) in plan.items():
            node = compose(config_name="closedloop", overrides=overrides).closedloop
            names = [str(d) for d in node.detectors]
            comp = compose(
                config_name="compare", overrides=[f"comparison={family}"]
            ).comparison
            shown = dict(cfg.closedloop.detector.get(name) or {})
            for est in comp.estimators:
                pick, why = closedloop_pick(name, str(est), True, names, shown)
                assert pick is not None, f"{family}.{est}: {why}"
                run = node.runs[node.detectors[pick].run]
                assert run.experiment  # a training run the scenario can make


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
    assert (
        "tactip",
        "-",
        "-",
        "closed loop tactip failed (see the demo's stderr)",
    ) == (row[1].strip(), row[6].strip(), row[7].strip(), row[9].strip())
    assert "closed loop tactip: skipped: parity check failed for fsr_robust" in err


def test_a_rerun_clears_the_familys_bundle_under_the_other_verdict(
    tmp_path: Path,
) -> None:
    # a bundle from an earlier run: recommended then, not recommended now (or the
    # other way round); the export writes one place, so the other must not keep it
    from slipkit._files import BUNDLE_FORMAT
    from slipkit.demo import clear_family_bundles, export_dir

    out = tmp_path / "demo"
    for recommended in (True, False):
        b = export_dir(out, "fsr", recommended=recommended)
        b.mkdir(parents=True)
        (b / "manifest.json").write_text(json.dumps({"format": BUNDLE_FORMAT}))
        b.with_name(f"{b.name}.export.log").write_text("log\n")
    other = export_dir(out, "tactip", recommended=True)
    other.mkdir(parents=True)
    (other / "manifest.json").write_text(json.dumps({"format": BUNDLE_FORMAT}))
    mine = export_dir(out, "davis", recommended=False)
    mine.mkdir(parents=True)
    (mine / "notes.txt").write_text("a user's folder, not a bundle\n")

    removed = clear_family_bundles(out, "fsr")
    assert sorted(removed) == sorted(
        export_dir(out, "fsr", recommended=r) for r in (True, False)
    )
    assert not any((out / "exports").rglob("fsr*"))
    assert clear_family_bundles(out, "davis") == []
    assert (mine / "notes.txt").is_file()
    assert (other / "manifest.json").is_file()


def test_a_family_with_no_recommendation_names_its_closest_row_under_the_table() -> (
    None
):
    from slipkit.demo import not_recommended_lines

    best = {
        "fsr": {"estimator": "fsr_onset", "recommended": True},
        "sliptack": {
            "estimator": "calibrated",
            "recommended": False,
            "closest": "Closest to the budget: `calibrated` (rmse 17), over (2.4x)",
        },
    }
    assert not_recommended_lines(best) == [
        "",
        "- sliptack: Closest to the budget: `calibrated` (rmse 17), over (2.4x)",
    ]
    assert not_recommended_lines({"fsr": best["fsr"]}) == []


def test_clearing_never_follows_a_link_out_of_the_demo_folder(tmp_path: Path) -> None:
    from slipkit._files import BUNDLE_FORMAT
    from slipkit.demo import clear_family_bundles

    elsewhere = tmp_path / "lab" / "fsr"
    elsewhere.mkdir(parents=True)
    (elsewhere / "manifest.json").write_text(json.dumps({"format": BUNDLE_FORMAT}))
    out = tmp_path / "demo"
    out.mkdir()
    (out / "exports").symlink_to(tmp_path / "lab", target_is_directory=True)
    assert clear_family_bundles(out, "fsr") == []
    assert (elsewhere / "manifest.json").is_file()
