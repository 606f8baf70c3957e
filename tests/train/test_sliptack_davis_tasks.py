"""SlipTack speed / acceleration and DAVIS tasks: tiny train + evaluate runs end to end."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

import slipkit
from slipkit.data import save_dataset
from slipkit.sim.commands import build_scene
from slipkit.train.commands import evaluate_main, train_main


def compose_train(tmp_path: Path, experiment: str, *overrides: str) -> DictConfig:
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        return compose(
            config_name="train",
            overrides=[
                f"experiment={experiment}",
                f"run_dir={tmp_path / 'run'}",
                *overrides,
            ],
        )


def evaluate_unseen(
    tmp_path: Path, scene: str, n: int, *overrides: str
) -> dict[str, Any]:
    """Simulate ``n`` unseen trials of ``scene`` (seed 99), save them, evaluate the run."""
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        scfg = compose(config_name="simulate", overrides=[f"scene={scene}", *overrides])
    unseen = build_scene(scfg.scene).simulate(n, 99, progress=False)
    folder = save_dataset(unseen, tmp_path / "unseen")
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        ecfg = compose(
            config_name="evaluate",
            overrides=[f"run={tmp_path / 'run'}", f"dataset={folder}", "name=unseen"],
        )
    GlobalHydra.instance().clear()
    return json.loads(evaluate_main(ecfg).read_text())


def test_sliptack_speed_train_and_evaluate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A shrunk speed run fits one estimator per material, writes the Fig.-8 curve, evaluates."""
    cfg = compose_train(
        tmp_path,
        "sliptack_speed",
        "dataset.n_trials=6",
        "scene.model.duration_s=1.2",
        "scene.model.materials=[basswood,acrylic]",
        "detector.window=500",
        "detector.hop=50",
    )
    objective = train_main(cfg)
    run = tmp_path / "run"
    metrics = json.loads((run / "metrics.json").read_text())
    assert objective == pytest.approx(metrics["validation"]["overall"]["mae_mm_s"])
    assert {"*"} <= set(metrics["stick_length_mm"])
    curve = pd.read_csv(run / "speed_trials.csv")
    assert len(metrics["split"]["test"]) == len(curve)
    assert (run / "frequency_vs_speed.png").stat().st_size > 0
    assert "f_model_basswood_hz" in pd.read_csv(run / "model_curve.csv").columns
    printed = capsys.readouterr().out
    assert "follows model" in printed
    assert str(run) == printed.strip().splitlines()[-1]
    scores = evaluate_unseen(
        tmp_path,
        "sliptack_pull",
        3,
        "scene.model.duration_s=1.2",
        "scene.model.materials=[basswood]",
    )
    assert 3 == scores["test"]["overall"]["n_trials"]
    # basswood follows the model: the estimate is within 15% of the true speed.
    assert scores["test"]["basswood"]["mean_rel_err_pct"] < 15.0


def test_sliptack_accel_train_and_evaluate(tmp_path: Path) -> None:
    """A shrunk drop run calibrates eq. 4 and eq. 5 and scores both on unseen trials."""
    cfg = compose_train(tmp_path, "sliptack_accel", "dataset.n_trials=8")
    objective = train_main(cfg)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    validation = metrics["validation"]
    assert ("group-kfold by trial", 3) == (validation["cv"], validation["k"])
    assert objective == pytest.approx(validation["deflection"]["rmse_m_s2"])
    assert {"deflection", "frequency_slope"} == set(metrics["test"])
    assert metrics["calibration"]["deflection"]["coef"] < 0
    scores = evaluate_unseen(tmp_path, "sliptack_drop", 4)
    assert 4 == scores["test"]["deflection"]["n_trials"]
    assert scores["test"]["deflection"]["rmse_m_s2"] < 1.5


def test_davis_release_train_and_evaluate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A shrunk DAVIS run prints slipkit's scores beside the paper's and evaluates."""
    cfg = compose_train(
        tmp_path, "davis_release", "dataset.n_trials=4", "scene.model.hold_s=0.3"
    )
    objective = train_main(cfg)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert objective == pytest.approx(metrics["validation"]["mean"]["f1"])
    assert 0.70 == metrics["paper"]["precision"]
    assert "paper" in capsys.readouterr().out
    assert (tmp_path / "run" / "davis_trials.csv").stat().st_size > 0
    scores = evaluate_unseen(tmp_path, "davis_release", 2, "scene.model.hold_s=0.3")
    assert 2 == scores["test"]["n_trials"]
    assert 0.0 <= scores["test"]["mean"]["sensitivity"] <= 1.0
