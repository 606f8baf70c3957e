"""Learned against analytic in every family (issue 14): each comparison holds both kinds, on tiny data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.compare.commands import compare_main


def _run(tmp_path: Path, family: str, overrides: list[str]) -> pd.DataFrame:
    """Run ``comparison=<family>`` with ``overrides`` under ``tmp_path``; its metrics table."""
    out = tmp_path / family
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="compare",
            overrides=[
                f"comparison={family}",
                f"out={out}",
                "progress=false",
                "cost.max_frames=100",
                "cost.warmup=2",
                *overrides,
            ],
        )
    compare_main(cfg)
    return pd.read_csv(out / "metrics.csv")


def test_tactip_svms_beside_the_pin_motion_detector(tmp_path: Path) -> None:
    """TacTip: the SVMs (frame task) and PinMotionDetector (pins stream) share one split, both exported."""
    df = _run(
        tmp_path,
        "tactip",
        [
            "comparison.dataset.n_trials=6",
            "comparison.task_overrides.svm_rbf_tuned.search.n_trials=2",
        ],
    )
    kinds = dict(zip(df["estimator"], df["kind"], strict=True))
    assert "analytic" == kinds["alignment"]
    assert "learned" == kinds["svm_rbf"]
    assert ["ok"] * len(df) == df["export"].tolist()
    assert True == bool(np.isfinite(df["delay_ms"]).all())  # noqa: E712


def test_fsr_window_classifier_beside_the_paper_detector(tmp_path: Path) -> None:
    """FSR (hard scene): a learned window classifier beside the analytic detectors, disturbances counted."""
    df = _run(tmp_path, "fsr", ["comparison.dataset.n_trials=4"])
    kinds = dict(zip(df["estimator"], df["kind"], strict=True))
    assert "learned" == kinds["window_logreg"]
    assert "analytic" == kinds["fsr_robust"]
    assert "analytic" == kinds["fsr_paper"]
    assert True == bool((df["disturbances"] > 0).all())  # noqa: E712
    assert True == bool(df["alarms_per_disturbance"].between(0, 1).all())  # noqa: E712
    exports = dict(zip(df["estimator"], df["export"], strict=True))
    assert "ok" == exports["window_logreg"]


def test_biotac_slip_window_classifier_beside_the_analytic_detectors(
    tmp_path: Path,
) -> None:
    """BioTac slip (hard lift): a learned pac window classifier beside pressure and force-derivative rules."""
    df = _run(tmp_path, "biotac_slip", ["comparison.dataset.n_trials=4"])
    kinds = dict(zip(df["estimator"], df["kind"], strict=True))
    assert {
        "pressure_vibration": "analytic",
        "force_derivative": "analytic",
        "window_logreg": "learned",
    } == kinds
    assert True == bool(np.isfinite(df["roc_auc"]).all())  # noqa: E712
