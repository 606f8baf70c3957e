"""slipkit closedloop scenario=sliptack: bundles in the loop between the oracle and no detector."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from slipkit import config_dir
from slipkit.closedloop.commands import closedloop_main
from slipkit.errors import SlipkitError


def _run(folder: Path, overrides: list[str]) -> None:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="closedloop",
            overrides=["closedloop=sliptack", f"out={folder}", *overrides],
        )
        closedloop_main(cfg)
    GlobalHydra.instance().clear()


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """One small SlipTack run: the energy bundle (8 training trials), 1 seed, 2 trials per condition."""
    folder = tmp_path_factory.mktemp("sliptack") / "cl"
    _run(
        folder,
        [
            "seeds=[0]",
            "trials_per_speed=2",
            "train_trials=8",
            "~closedloop.detectors.energy_k3",
            "~closedloop.detectors.speed_10",
            "~closedloop.detectors.exact",
            "~closedloop.detectors.paper_form",
            "~closedloop.detectors.calibrated",
            "~closedloop.detectors.spectral_gbr",
            "~closedloop.runs.speed",
            "~closedloop.detectors.onset",
            "~closedloop.detectors.onset_logistic",
            "~closedloop.runs.onset",
            "~closedloop.runs.onset_logistic",
        ],
    )
    yield folder
    GlobalHydra.instance().clear()


def _slide(folder: Path) -> pd.Series:
    """Mean slide per detector over every trial (a lost object counts its travel), mm."""
    results = pd.read_csv(folder / "results.csv")
    return results.groupby("detector")["slip_mm"].mean()


def _quiet_slide(folder: Path, detector: str) -> pd.Series:
    """Mean slide per detector over the trials where ``detector`` raised no false alarm
    (an early grip step can pre-empt a slide), mm."""
    results = pd.read_csv(folder / "results.csv")
    key = ["seed", "condition_index", "trial"]
    quiet = results[
        (results["detector"] == detector) & ~results["false_alarm"].astype(bool)
    ][key]
    return results.merge(quiet, on=key).groupby("detector")["slip_mm"].mean()


def test_bundle_lies_between_oracle_and_no_detector(small: Path) -> None:
    """Mean slide over the trials where the bundle raised no false alarm: zero-delay
    oracle <= energy bundle <= no detector (every object lost)."""
    slide = _quiet_slide(small, "energy_k1")
    summary = pd.read_csv(small / "summary.csv").set_index("detector")
    assert (True, True, 100.0) == (
        bool(slide["oracle"] <= slide["energy_k1"]),
        bool(slide["energy_k1"] <= slide["none"]),
        float(summary.loc["none", "dropped_pct"]),
    )


def test_later_oracle_gives_more_slide(small: Path) -> None:
    """The delayed oracles (0, 25, 50, 100 ms) slide strictly more with each delay."""
    slide = _slide(small)
    names = ["oracle", "oracle+25ms", "oracle+50ms", "oracle+100ms"]
    assert True == all(  # noqa: E712
        slide[a] < slide[b] for a, b in itertools.pairwise(names)
    )


def test_outputs_cover_pull_and_drop(small: Path) -> None:
    """results.csv holds 3 pull speeds and the drop for every detector; report and plot exist."""
    results = pd.read_csv(small / "results.csv")
    detectors = {"energy_k1", "oracle", "none"} | {
        f"oracle+{d}ms" for d in (25, 50, 100)
    }
    assert (
        [0.0, 10.0, 31.6, 100.0],
        detectors,
        len(detectors) * 4 * 2,
        True,
    ) == (
        sorted(results["condition"].unique().tolist()),
        set(results["detector"]),
        len(results),
        (small / "report.md").read_text().startswith("# Closed loop: sliptack"),
    )


def test_bad_plant_override_is_refused(tmp_path: Path) -> None:
    """closedloop.plant.motor_s < 0 is a one-line SlipkitError naming the field."""
    with pytest.raises(SlipkitError, match=r"closedloop\.plant\.motor_s"):
        _run(
            tmp_path / "cl",
            ["closedloop.plant.motor_s=-1"],
        )


@pytest.mark.slow
def test_default_scenario_keeps_the_order_and_exports_the_threshold(
    tmp_path: Path,
) -> None:
    """The default run (3 seeds), on the trials without a false alarm of the energy
    bundle: oracle <= energy <= none; the speed graph carries 10 mm/s."""
    import json

    folder = tmp_path / "cl"
    _run(folder, [])
    slide = _quiet_slide(folder, "energy_k1")
    manifest = json.loads(
        (folder / "bundles" / "speed_10" / "manifest.json").read_text()
    )
    assert (True, True, 10.0) == (
        bool(slide["oracle"] <= slide["energy_k1"]),
        bool(slide["energy_k1"] <= slide["none"]),
        float(manifest["threshold"]),
    )


def test_onset_bundle_beats_the_25ms_oracle_without_false_alarms(
    tmp_path: Path,
) -> None:
    """The nib-rate onset bundle (seed 0, 2 trials per condition) raises no false
    alarm, catches every object and declares sooner than the oracle lagging 25 ms."""
    folder = tmp_path / "cl"
    _run(
        folder,
        [
            "seeds=[0]",
            "trials_per_speed=2",
            "~closedloop.detectors.energy_k1",
            "~closedloop.detectors.energy_k3",
            "~closedloop.detectors.speed_10",
            "~closedloop.detectors.exact",
            "~closedloop.detectors.paper_form",
            "~closedloop.detectors.calibrated",
            "~closedloop.detectors.spectral_gbr",
            "~closedloop.detectors.onset_logistic",
            "~closedloop.runs.speed",
            "~closedloop.runs.energy",
            "~closedloop.runs.onset_logistic",
            "closedloop.oracle_delays_ms=[25]",
        ],
    )
    summary = pd.read_csv(folder / "summary.csv").set_index("detector")
    row = summary.loc["onset"]
    assert (0.0, 100.0, True) == (
        float(row["false_alarm_pct"]),
        float(row["caught_pct"]),
        bool(row["delay_ms"] < summary.loc["oracle+25ms", "delay_ms"]),
    )
