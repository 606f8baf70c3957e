"""``slipkit export`` of analytic-detector runs: a bundle whose loop decides as the batch detector."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.export.commands import export_main
from slipkit.runtime import StreamLoop, load_bundle
from slipkit.train.commands import train_main
from slipkit.train.runs import read_run

DETECTORS = {
    "fsr": ["experiment=fsr_roc", "dataset.n_trials=4"],
    "force_derivative": [
        "experiment=biotac_slip_detect",
        "detector=force_derivative",
        "task.stream=truth_force",
        "task.channels=[fx,fy]",
        "task.compare=[]",
        "dataset.n_trials=4",
    ],
    "pressure_fixed_baseline": [
        "experiment=biotac_slip_detect",
        "detector.baseline=3.0",
        "task.compare=[]",
        "dataset.n_trials=4",
    ],
}


def _compose(name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One tiny run per exportable detector."""
    root = tmp_path_factory.mktemp("detector_runs")
    for name, overrides in DETECTORS.items():
        train_main(_compose("train", [*overrides, f"run_dir={root / name}"]))
    return {name: root / name for name in DETECTORS}


@pytest.mark.parametrize("name", sorted(DETECTORS))
def test_detector_bundle_decides_as_the_batch_detector(
    name: str, runs: dict[str, Path], tmp_path: Path
) -> None:
    """The loop's decisions on the replay match the batch detector's at the same samples."""
    out = tmp_path / name
    export_main(
        _compose("export", [f"run={runs[name]}", f"out={out}", "choose_session=false"])
    )
    bundle = load_bundle(out)
    m = bundle.manifest
    replay = np.load(out / "replay.npz")
    frames, times = replay["frames"], replay["timestamps"]
    loop = StreamLoop(bundle)
    for values, ts in zip(frames, times, strict=True):
        loop.step(values, float(ts))
    res = loop.result()
    detector = read_run(runs[name]).model
    ref = np.asarray(detector.decision_function(frames))[res.frame]
    thr = float(m.decision.threshold or 0.0)
    agree = float(np.mean((ref >= thr) == res.slip))
    assert len(res.frame) > 0
    assert agree >= 0.999
    raw = json.loads((out / "manifest.json").read_text())
    assert raw["frame"]["window"] >= 1
    assert "1" == raw["decision"]["positive"]


def test_fsr_bundle_has_the_fsr_budget_and_the_graph_window(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """FSR: one voltage sample per frame, the graph's 10-sample window every 5, p99 <= 0.05 ms."""
    out = tmp_path / "fsr"
    export_main(
        _compose("export", [f"run={runs['fsr']}", f"out={out}", "choose_session=false"])
    )
    raw = json.loads((out / "manifest.json").read_text())
    assert [10, 5, [1]] == [
        raw["frame"]["window"],
        raw["frame"]["hop"],
        raw["frame"]["shape"],
    ]
    assert pytest.approx(0.05) == raw["budget_ms"]["p99"]
