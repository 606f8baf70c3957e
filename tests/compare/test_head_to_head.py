"""Learned against analytic in every family (issue 14): each comparison holds both kinds, on tiny data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.compare.commands import compare_main
from slipkit.families.biotac.electrode_energy import ElectrodeEnergyClassifier
from slipkit.families.davis.classifier import EventFrameClassifier
from slipkit.families.sliptack.spectral import SpectralSpeedRegressor


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
    assert ("analytic", "analytic") == (kinds["alignment"], kinds["alignment_fast"])
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


def test_electrode_energy_tells_motion_from_touch() -> None:
    """Windows whose electrodes keep changing are motion (the most frequent one), still ones touch."""
    rng = np.random.default_rng(0)
    width, channels = 5, 3
    still = 100.0 + 0.1 * rng.standard_normal((20, width, channels))
    ramp = np.arange(width)[None, :, None] * rng.uniform(2.0, 4.0, (20, 1, channels))
    moving = 100.0 + ramp + 0.1 * rng.standard_normal((20, width, channels))
    X = np.concatenate([still, moving]).reshape(40, -1)
    y = np.array(["t"] * 20 + ["n"] * 14 + ["e"] * 6)
    clf = ElectrodeEnergyClassifier(n_channels=channels).fit(X, y)
    assert ["t"] * 20 + ["n"] * 20 == clf.predict(X).tolist()
    assert ["e", "n", "t"] == clf.classes_.tolist()


@pytest.mark.slow
@pytest.mark.realdata
def test_dos_real_energy_floor_beside_a_learned_window_model(
    shared_data: Path, tmp_path: Path
) -> None:
    """BioTacSP-DoS: the analytic energy classifier runs through the same window task as a learned model, and exports."""
    if not (shared_data / "biotacsp-dos").is_dir():
        pytest.skip("biotacsp-dos is not among the real recordings")
    df = _run(
        tmp_path,
        "dos_real",
        [
            f"comparison.dataset.raw={shared_data / 'biotacsp-dos'}",
            "~comparison.estimators.window_select",
            "~comparison.estimators.window_gru",
            "comparison.estimators.window_mlp.max_epochs=2",
            "comparison.task.folds=2",
            "comparison.task.dynamics=null",
            "comparison.task.first_frame_control=false",
        ],
    )
    kinds = dict(zip(df["estimator"], df["kind"], strict=True))
    assert {"window_mlp": "learned", "energy": "analytic"} == kinds
    exports = dict(zip(df["estimator"], df["export"], strict=True))
    # a touch-vs-motion graph (families/biotac/export/window_rules.py)
    assert "ok" == exports["energy"]


def test_event_frame_classifier_learns_the_positive_edge() -> None:
    """Frames dominated by positive (contact-lost) events inside the labelled span are called slip."""
    rng = np.random.default_rng(0)
    rows = []
    for f in range(20):  # 20 ms frames; slip from 0.2 s: many positive events
        n_pos, n_neg = (40, 5) if f >= 10 else (5, 5)
        for sign, n in ((1.0, n_pos), (-1.0, n_neg)):
            t = f * 0.02 + rng.uniform(0, 0.02, n)
            xy = rng.integers(0, 50, (n, 2))
            rows.append(np.column_stack([t, xy, np.full(n, sign)]))
    ev = np.concatenate(rows)
    ev = ev[np.argsort(ev[:, 0], kind="stable")]
    clf = EventFrameClassifier().fit(ev, onsets=[0.2], ends=[np.inf])
    assert [False] * 10 + [True] * 10 == clf.frames(ev)["slip"].tolist()


@pytest.mark.slow  # ~20 s under load; test_compare's DAVIS test runs the same rows by default
def test_davis_learned_frames_beside_the_polarity_rule(tmp_path: Path) -> None:
    """DAVIS (hard release): the event-frame logistic regression and the polarity rule share the bins."""
    df = _run(tmp_path, "davis", ["comparison.dataset.n_trials=4"])
    kinds = dict(zip(df["estimator"], df["kind"], strict=True))
    assert {
        "polarity_lines": "analytic",
        "polarity_square": "analytic",
        "onset": "analytic",
        "event_logreg": "learned",
    } == kinds
    assert True == bool((df["export"] == "ok").all())  # noqa: E712 - all export (issue 14)
    assert True == bool(np.isfinite(df["f1"]).all())  # noqa: E712


def test_spectral_regressor_learns_speed_from_the_vibration_frequency() -> None:
    """Speeds proportional to the vibration frequency are learned and held between hops (mm/s)."""
    rate, n = 1000.0, 1500
    t = np.arange(n) / rate
    xs, ys, segs = [], [], []
    for i, f in enumerate([20.0, 30.0, 40.0, 50.0, 60.0, 70.0]):
        xs.append(np.sin(2 * np.pi * f * t))
        ys.append(np.full(n, f / 2))  # speed (mm/s) = f / 2
        segs.append(np.full(n, i))
    reg = SpectralSpeedRegressor(window=400, hop=50, model="ridge", alpha=1e-3)
    reg.fit(
        np.concatenate(xs)[:, None], np.concatenate(ys), segments=np.concatenate(segs)
    )
    pred = reg.predict(np.sin(2 * np.pi * 45.0 * t)[:, None])
    assert True == bool(np.isnan(pred[:399]).all())  # noqa: E712 - before the first window
    assert 22.5 == pytest.approx(float(np.median(pred[399:])), abs=2.0)


@pytest.mark.slow  # ~35 s under load (a 1 s spectrum every 50 ms on every pull)
def test_sliptack_spectral_regressor_beside_the_analytic_inversion(
    tmp_path: Path,
) -> None:
    """SlipTack (hard pull): the learned spectral regressor beside eq. 3 inverted, both exported."""
    df = _run(
        tmp_path,
        "sliptack",
        [
            "comparison.dataset.n_trials=6",
            "~comparison.estimators.paper_form",
            "~comparison.estimators.calibrated",
            "~comparison.estimators.onset",
            "~comparison.estimators.onset_logistic",
        ],
    )
    kinds = dict(zip(df["estimator"], df["kind"], strict=True))
    assert {"exact": "analytic", "spectral_gbr": "learned"} == kinds
    exports = dict(zip(df["estimator"], df["export"], strict=True))
    assert "ok" == exports["spectral_gbr"]  # exports since issue 14's exporter
    assert True == bool(np.isfinite(df["rmse"]).all())  # noqa: E712


@pytest.mark.slow  # ~25 s: the exact inversion's 1 s spectra on every pull
def test_sliptack_onset_detectors_share_the_speed_split(tmp_path: Path) -> None:
    """SlipTack (hard pull): the onset detectors run on the speed estimators' split
    (the run checks it) and catch every test slip without an early alarm."""
    df = _run(
        tmp_path,
        "sliptack",
        [
            "~comparison.estimators.paper_form",
            "~comparison.estimators.calibrated",
            "~comparison.estimators.spectral_gbr",
            "~comparison.estimators.onset_logistic",
        ],
    )
    row = df.set_index("estimator").loc["onset"]
    assert (1.0, 0.0, "ok") == (
        float(row["detected_rate"]),
        float(row["early_alarm_rate"]),
        row["export"],
    )


def _compose_comparison(family: str, overrides: list[str] | None = None):
    """The composed ``comparison=<family>`` node (no run)."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="compare",
            overrides=[f"comparison={family}", *(overrides or [])],
        )
    return cfg.comparison


def test_biotac_force_runs_on_the_hard_probe_with_analytic_and_learned() -> None:
    """BioTac force: the hard probe by default, the base probe as an override, normals beside the MLPs."""
    comp = _compose_comparison("biotac_force")
    base = _compose_comparison(
        "biotac_force", ["scene@comparison.scene=biotac_force_probe"]
    )
    assert "biotac_force_probe_hard" == comp.scene.name
    assert "biotac_force_probe" == base.scene.name
    assert ["normals"] == list(comp.analytic)
    assert {"lwr", "mlp1", "mlp3"} == set(comp.estimators) - set(comp.analytic)


def test_biotac_slip_type_holds_the_twist_rule_beside_the_window_nets() -> None:
    """BioTac slip type: the hard lift by default, the analytic twist share beside the window nets."""
    comp = _compose_comparison("biotac_slip_type")
    assert "biotac_lift_slip_hard" == comp.scene.name
    assert ["twist"] == list(comp.analytic)
    assert (
        "slipkit.families.biotac.slip_twist.SlipTwistClassifier"
        == comp.estimators.twist._target_
    )
    assert {"window_mlp", "window_cnn"} == set(comp.estimators) - set(comp.analytic)
