"""A multi-class window model deploys with its meaning: slip classes, per-class counts, every class replayed, the data's rate."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.data import Dataset, LabelSpec, StreamSpec, Trial, save_dataset
from slipkit.errors import SlipkitError
from slipkit.export.commands import _budget, export_main
from slipkit.runtime import ReplaySource, StreamLoop, load_bundle
from slipkit.train.commands import train_main

CLASSES = ("n", "e", "s", "w", "t")
RATE_HZ = 50.0  # not the BioTac SP family's 300 Hz: the budget must follow the data
N_FRAMES = 40
CHANNELS = ("e1", "e2", "e3", "e4")
#: direction of each class's drift over the 4 channels (t: none)
DRIFT = {
    "n": [1, 0, 0, 0],
    "e": [0, 1, 0, 0],
    "s": [0, 0, 1, 0],
    "w": [0, 0, 0, 1],
    "t": [0, 0, 0, 0],
}


def _dataset() -> Dataset:
    """5 classes x 4 objects x 2 trials of 40 frames at 50 Hz, in class order (as DoS)."""
    rng = np.random.default_rng(0)
    trials = []
    for cls in CLASSES:
        for obj in range(4):
            for rep in range(2):
                t = np.arange(N_FRAMES) / RATE_HZ
                x = np.outer(t, DRIFT[cls]) * 20.0 + rng.normal(
                    scale=0.2, size=(N_FRAMES, len(CHANNELS))
                )
                table = pd.DataFrame(x, columns=list(CHANNELS))
                table.insert(0, "t", t)
                trials.append(
                    Trial(
                        f"{cls}/obj{obj}-{rep}",
                        {"electrodes": table},
                        labels={"slip_class": cls},
                        meta={"object": f"obj{obj}"},
                    )
                )
    return Dataset.from_trials(
        trials,
        sensor="biotac_sp",
        streams={
            "electrodes": StreamSpec(
                "electrodes",
                CHANNELS,
                dict.fromkeys(CHANNELS, "counts"),
                rate_hz=RATE_HZ,
            )
        },
        labels={"slip_class": LabelSpec("slip_class", classes=CLASSES)},
        groups=("object",),
        provenance={"scene": "unit-test"},
        name="multiclass",
    )


def _compose(name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2-fold leave-objects-out run of a scikit-learn pipeline (window statistics -> logistic)."""
    root = tmp_path_factory.mktemp("mc")
    save_dataset(_dataset(), root / "data")
    train_main(
        _compose(
            "train",
            [
                f"dataset.path={root / 'data'}",
                "task=window_slip_type",
                "task.window=4",
                "task.hop=2",
                "task.onset_label=null",
                "task.split=group",
                "task.folds=2",
                "task.first_frame_control=false",
                "task.dynamics=null",
                "model=window_stats_lr",
                f"model._args_.0.n_channels={len(CHANNELS)}",
                f"run_dir={root / 'run'}",
            ],
        )
    )
    return root / "run"


def _export(run: Path, out: Path, *extra: str) -> dict:
    export_main(
        _compose("export", [f"run={run}", f"out={out}", "choose_session=false", *extra])
    )
    loaded: dict = json.loads((out / "manifest.json").read_text())
    return loaded


def test_manifest_names_classes_slip_classes_and_the_datas_frame_period(
    run: Path, tmp_path: Path
) -> None:
    """Default slip classes are all but t; the frame period is 1000 / 50 Hz; refit and scoring are told."""
    m = _export(run, tmp_path / "b")
    assert sorted(CLASSES) == sorted(m["decision"]["classes"])
    assert ["e", "n", "s", "w"] == sorted(m["decision"]["slip_classes"])
    assert {"frame_period": 20.0, "p99": 2.0, "source": "data_rate_hz"} == m[
        "budget_ms"
    ]
    training = m["training"]
    assert (True, False, False) == (
        training["refit_on_all_data"],
        training["held_out"],
        training["replay"]["held_out"],
    )
    assert (
        "2-fold leave-objects-out CV (outer folds), before the refit"
        == (training["scored_on"])
    )


def test_bounded_replay_holds_every_class(run: Path, tmp_path: Path) -> None:
    """Room for 5 of the 40 trials: one trial of each class (not the first 5, all 'n')."""
    m = _export(run, tmp_path / "b", f"replay_max_frames={5 * N_FRAMES}")
    assert dict.fromkeys(CLASSES, 1) == m["training"]["replay"]["by_class"]
    replay = np.load(tmp_path / "b" / "replay.npz")
    assert (5 * N_FRAMES, 5 * N_FRAMES) == (
        len(replay["frames"]),
        m["training"]["replay"]["frames"],
    )


def test_loop_counts_decisions_per_class_and_slip_is_any_slip_class(
    run: Path, tmp_path: Path
) -> None:
    """The runtime's summary counts each class; slip decisions are the decisions not decided t."""
    _export(run, tmp_path / "b")
    bundle = load_bundle(tmp_path / "b")
    replay = np.load(tmp_path / "b" / "replay.npz")
    summary = (
        StreamLoop(bundle)
        .run(ReplaySource(replay["frames"], replay["timestamps"]))
        .summary()
    )
    by_class = summary["decisions_by_class"]
    assert sorted(CLASSES) == sorted(by_class)
    assert summary["decisions"] == sum(by_class.values())
    assert summary["decisions"] - by_class["t"] == summary["slip_decisions"]
    # the drifts are easy: every class is decided on some window
    assert all(0 < n for n in by_class.values())


def test_slip_classes_option_and_an_unknown_class(run: Path, tmp_path: Path) -> None:
    """slip_classes=[n,e] is written as given; a class the model lacks is refused, no bundle written."""
    m = _export(run, tmp_path / "b", "slip_classes=[n,e]")
    assert ["n", "e"] == m["decision"]["slip_classes"]
    with pytest.raises(SlipkitError, match="slip_classes"):
        _export(run, tmp_path / "c", "slip_classes=[n,up]")
    assert not (tmp_path / "c").exists()


def test_slipkit_run_check_reports_per_class_decisions(
    run: Path, tmp_path: Path
) -> None:
    """`slipkit-run --check` prints the per-class line and the replay's held_out note."""
    _export(run, tmp_path / "b")
    proc = subprocess.run(
        [sys.executable, "-m", "slipkit.runtime.cli", str(tmp_path / "b"), "--check"],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    assert (0, "") == (proc.returncode, proc.stderr)
    lines = proc.stdout.splitlines()
    assert 1 == sum(line.startswith("decisions by class: ") for line in lines)
    assert 1 == sum("held_out: false" in line for line in lines)


def test_sensor_default_period_only_without_a_data_rate() -> None:
    """A stream with no rate_hz takes the sensor family's period (BioTac SP: 3.333 ms), and says so."""
    cfg = _compose("export", ["run=x"])
    dataset = SimpleNamespace(
        sensor="biotac_sp", streams={"electrodes": SimpleNamespace(rate_hz=None)}
    )
    budget = _budget(cfg, dataset, {"streams": ["electrodes"], "rate_hz": 300.03})
    assert {
        "frame_period": 3.333,
        "p99": pytest.approx(0.3333),
        "source": "sensor_default",
    } == budget


@pytest.mark.slow
@pytest.mark.realdata
def test_real_dos_bundle_checks_every_direction_on_its_10_ms_frame(
    shared_data: Path, tmp_path: Path
) -> None:
    """BioTacSP-DoS: export slips on every direction against t, 100 Hz budget, all 7 classes replayed; slipkit-run --check passes."""
    if not (shared_data / "biotacsp-dos").is_dir():
        pytest.skip("biotacsp-dos is not among the real recordings")
    train_main(
        _compose(
            "train",
            [
                "experiment=dos_real",
                f"dataset.raw={shared_data / 'biotacsp-dos'}",
                # a fixed scikit-learn pipeline, not the experiment's nested model search
                "model=window_stats_lr",
                "task.sweep=[]",
                "~task.compare",
                "task.first_frame_control=false",
                "task.dynamics=null",
                f"run_dir={tmp_path / 'run'}",
            ],
        )
    )
    m = _export(tmp_path / "run", tmp_path / "b")
    directions = ["aw", "cw", "e", "n", "s", "w"]
    assert (directions, ["t"]) == (
        sorted(m["decision"]["slip_classes"]),
        sorted(set(m["decision"]["classes"]) - set(m["decision"]["slip_classes"])),
    )
    assert {"frame_period": 10.0, "p99": 1.0, "source": "data_rate_hz"} == m[
        "budget_ms"
    ]
    replay = m["training"]["replay"]
    assert (sorted([*directions, "t"]), False) == (
        sorted(replay["by_class"]),
        replay["held_out"],
    )
    assert (True, False) == (
        m["training"]["refit_on_all_data"],
        m["training"]["held_out"],
    )
    summary = tmp_path / "s.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "slipkit.runtime.cli",
            str(tmp_path / "b"),
            "--replay",
            str(tmp_path / "b" / "replay.npz"),
            "--check",
            "--json",
            str(summary),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert (0, "") == (proc.returncode, proc.stderr)
    got = json.loads(summary.read_text())
    by_class = got["decisions_by_class"]
    assert sorted([*directions, "t"]) == sorted(by_class)
    assert got["decisions"] - by_class["t"] == got["slip_decisions"]
    assert 0 < got["slip_decisions"]
