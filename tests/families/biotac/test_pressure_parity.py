"""BioTac pressure-vibration export parity (issue 16): the graph is checked against the
fixed-baseline detector it computes, not the per-recording one it was trained as."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.export.commands import export_main
from slipkit.export.deploy import deployment
from slipkit.export.detectors import check_detector_parity
from slipkit.export.registry import ExportError
from slipkit.families.biotac.detectors import PressureVibration
from slipkit.families.biotac.export.detectors import (
    baseline_agreement,
    export_pressure_vibration,
    pressure_baseline,
    with_fixed_baseline,
)
from slipkit.runtime import StreamLoop, load_bundle
from slipkit.train.commands import build, train_main
from slipkit.train.data import training_dataset
from slipkit.train.runs import read_run

Arr = np.ndarray


def _recordings(levels: tuple[float, ...], seed: int = 0) -> tuple[Arr, Arr, Arr]:
    """One 2000-sample recording per noise level (counts): noise, then a 300 Hz
    vibration burst (in the 60-700 Hz band) from sample 1200 at 6x the level; slip
    labels and segments."""
    rng = np.random.default_rng(seed)
    xs, ys, segs = [], [], []
    t = np.arange(2000) / 2200.0
    for k, level in enumerate(levels):
        x = 2048.0 + level * rng.standard_normal(2000)
        x[1200:] += 6.0 * level * np.sin(2 * np.pi * 300.0 * t[1200:])
        xs.append(np.round(x))
        ys.append((np.arange(2000) >= 1200).astype(int))
        segs.append(np.full(2000, k))
    return np.concatenate(xs)[:, None], np.concatenate(ys), np.concatenate(segs)


def test_per_recording_baselines_break_parity_and_the_fixed_baseline_restores_it() -> (
    None
):
    """Graph vs per-recording detector disagrees far from k; vs its fixed-baseline copy it agrees."""
    X, y, seg = _recordings((3.0, 6.0, 4.0, 8.0, 5.0))
    trained = PressureVibration().fit(X, y, segments=seg)  # baseline per recording
    base = pressure_baseline(trained, X, segments=seg)
    deployed = with_fixed_baseline(trained, base)
    graph = export_pressure_vibration(deployed)
    wrong = check_detector_parity(trained, graph, X, segments=seg)
    right = check_detector_parity(deployed, graph, X, segments=seg)
    assert (False, False) == (wrong["passed"], wrong["disagreements_near_threshold"])
    assert (True, 0) == (right["passed"], right["n_disagree"])
    assert (None, base, trained.threshold_) == (
        trained.baseline,
        deployed.baseline,
        deployed.threshold_,
    )
    agree, n = baseline_agreement(trained, deployed, X, segments=seg)
    assert agree < 1.0
    assert 5 * (2000 - 220) == n


def test_with_fixed_baseline_refuses_a_non_positive_baseline() -> None:
    """A zero or NaN baseline is refused with a message naming it."""
    X, y, seg = _recordings((3.0,))
    det = PressureVibration().fit(X, y, segments=seg)
    for bad in (0.0, float("nan")):
        with pytest.raises(ExportError, match="baseline"):
            with_fixed_baseline(det, bad)


def _compose(name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


def test_export_of_a_per_recording_run_passes_parity_and_states_the_gap(
    tmp_path: Path,
) -> None:
    """The 8-trial run that failed parity exports; its loop decides as the fixed-baseline detector."""
    run_dir = tmp_path / "run"
    train_main(
        _compose(
            "train",
            [
                "experiment=biotac_slip_detect",
                "dataset.n_trials=8",
                "task.compare=[]",
                f"run_dir={run_dir}",
            ],
        )
    )
    out = tmp_path / "bundle"
    export_main(
        _compose("export", [f"run={run_dir}", f"out={out}", "choose_session=false"])
    )
    raw = json.loads((out / "manifest.json").read_text())
    run = read_run(run_dir)
    trained = run.model
    dep = deployment(
        build(run.config.task, "task"), run, training_dataset(run.config), {}
    )
    deployed = dep.model
    replay = np.load(out / "replay.npz")
    frames, times = replay["frames"], replay["timestamps"]
    loop = StreamLoop(load_bundle(out))
    for values, ts in zip(frames, times, strict=True):
        loop.step(values, float(ts))
    res = loop.result()
    ref = deployed.decision_function(frames)[res.frame] >= deployed.threshold_
    assert (None, True) == (trained.baseline, deployed.baseline > 0)
    assert ref.tolist() == np.asarray(res.slip, dtype=bool).tolist()
    assert "decides as the trained detector on" in raw["description"]
