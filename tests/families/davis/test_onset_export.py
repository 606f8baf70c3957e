"""The DAVIS onset rule's graph computes the detector's score on event frames."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.export import export
from slipkit.export.parity import run_graph
from slipkit.families.davis.export.onset import DavisOnsetScores
from slipkit.families.davis.onset import DavisOnset


def _compose(name: str, overrides: list[str]) -> DictConfig:
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    GlobalHydra.instance().clear()
    return cfg


def test_graph_score_equals_detector_score() -> None:
    """Random sparse frames and a strip: the ONNX score equals DavisOnset's, signs included."""
    h, w = 30, 40
    rng = np.random.default_rng(0)
    frames = (rng.random((6, 2, h, w)) < 0.15) * rng.integers(1, 3, (6, 2, h, w))
    frames[0] = 0
    frames[0, 0, 5:25, 10:12] = 1  # a straight strip lost: slip
    frames[1, 0] = 0  # nothing lost
    det = DavisOnset(width_px=w, height_px=h, min_pos_px=6).fit(np.empty((0, 4)))
    scores = DavisOnsetScores(detector=det).fit()
    got = run_graph(export(scores), frames.astype(np.float32)).ravel()
    want = scores.decision_function(frames)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert want[0] > 0
    assert (want[1:] <= 0).all()


def test_bundle_deploys_the_runs_chosen_debounce(tmp_path: Path) -> None:
    """An onset run whose training trials chose k = 2: the bundle's manifest says 2."""
    from slipkit.export.commands import export_main
    from slipkit.train.commands import train_main

    run = tmp_path / "run"
    train_main(
        _compose(
            "train",
            [
                "experiment=davis_release",
                "detector=davis_onset",
                "dataset.n_trials=4",
                "scene.model.hold_s=0.3",
                "task.operating_point.debounce=[2]",
                f"run_dir={run}",
            ],
        )
    )
    metrics = json.loads((run / "metrics.json").read_text())
    out = tmp_path / "bundle"
    export_main(
        _compose("export", [f"run={run}", f"out={out}", "choose_session=false"])
    )
    raw = json.loads((out / "manifest.json").read_text())
    assert [2, 2, 2] == [
        metrics["operating_point"]["debounce_k"],
        metrics["test"]["operating_point"]["debounce_k"],
        raw["debounce"]["k"],
    ]
    assert "training trials" in metrics["operating_point"]["from"]
