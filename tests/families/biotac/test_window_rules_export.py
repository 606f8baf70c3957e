"""The analytic window rules (DoS electrode energy, BioTac twist share) as ONNX graphs and bundles."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.data import Dataset, LabelSpec, StreamSpec, Trial, save_dataset
from slipkit.export import check_parity, export
from slipkit.export.parity import run_graph
from slipkit.export.registry import ExportError
from slipkit.families.biotac.electrode_energy import ElectrodeEnergyClassifier
from slipkit.families.biotac.export.window_rules import (
    export_electrode_energy,
    export_slip_twist,
)
from slipkit.families.biotac.slip_twist import SlipTwistClassifier
from slipkit.runtime import ReplaySource, StreamLoop, load_bundle

WIDTH, CHANNELS = 8, 4


def energy_windows(n: int = 120, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Flattened windows (counts near 3000): 't' holds still, 'e' / 'n' drift on one channel."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.array(["e", "n", "t"]), n // 3)
    x = 3000.0 + rng.normal(0.0, 2.0, (n, WIDTH, CHANNELS))
    ramp = np.linspace(0.0, 40.0, WIDTH)
    x[y == "e", :, 0] += ramp
    x[y == "n", :, 1] += ramp
    return x.reshape(n, -1), y


def twist_windows(n: int = 120, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Flattened windows: 'linear' moves every electrode one way, 'rotational' two ways."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.array(["linear", "rotational"]), n // 2)
    x = 2000.0 + rng.normal(0.0, 1.0, (n, WIDTH, CHANNELS))
    ramp = np.linspace(0.0, 30.0, WIDTH)[:, None]
    x[y == "linear"] += ramp * np.array([1.0, 0.8, 0.5, 0.3])
    x[y == "rotational"] += ramp * np.array([1.0, 0.6, -0.7, -0.9])
    return x.reshape(n, -1), y


def _with_bad_values(X: np.ndarray) -> np.ndarray:
    """A copy with a NaN value, a NaN electrode and an all-NaN window (the rules skip NaN)."""
    bad = X.copy()
    frames = bad.reshape(len(bad), WIDTH, CHANNELS)
    frames[0, 3, 1] = np.nan
    frames[1, :, 2] = np.nan
    frames[2] = np.nan
    return bad


@pytest.mark.filterwarnings("ignore:Mean of empty slice")  # the all-NaN window
@pytest.mark.parametrize("opset", [17, 18])
def test_energy_graph_scores_as_the_classifier(opset: int) -> None:
    """Electrode energy: the graph's score is decision_function (NaN rows too); parity passes."""
    X, y = energy_windows()
    clf = ElectrodeEnergyClassifier(n_channels=CHANNELS).fit(X, y)
    graph = export(clf, n_frames=WIDTH, opset=opset)
    # held-out windows: the ROC threshold is a training window's own energy (score 0)
    Xb = _with_bad_values(energy_windows(seed=1)[0])
    ours = run_graph(graph, Xb)
    ref = clf.decision_function(Xb.astype(np.float32))
    np.testing.assert_allclose(ours, ref, rtol=1e-6, atol=1e-4)
    report = check_parity(clf, graph, Xb)
    assert (True, 1.0) == (report["passed"], report["agreement"])


def test_energy_graph_is_a_motion_vs_touch_rule() -> None:
    """The energy bundle decides between touch and the motion class: classes (t, motion), >= 0."""
    X, y = energy_windows()
    clf = ElectrodeEnergyClassifier(n_channels=CHANNELS).fit(X, y)
    graph = export(clf, n_frames=WIDTH)
    Xh = energy_windows(seed=1)[0]
    decided = np.where(run_graph(graph, Xh) >= 0, graph.classes[1], graph.classes[0])
    assert ("t", clf.motion_class_, 0.0, False) == (
        *graph.classes,
        graph.threshold,
        graph.strict,
    )
    assert clf.predict(Xh).tolist() == decided.tolist()


@pytest.mark.parametrize("opset", [17, 18])
@pytest.mark.parametrize("width", [1, 3, WIDTH])
def test_twist_graph_scores_as_the_classifier(opset: int, width: int) -> None:
    """Twist share: the graph's score is decision_function for any window length, NaN too."""
    X, y = twist_windows()
    frames = X.reshape(len(X), WIDTH, CHANNELS)[:, :width]
    Xw = frames.reshape(len(X), -1)
    clf = SlipTwistClassifier(n_channels=CHANNELS).fit(Xw, y)
    graph = export(clf, n_frames=width, opset=opset)
    # held-out windows: the ROC threshold is a training window's own share (score 0)
    Xh = twist_windows(seed=1)[0].reshape(len(X), WIDTH, CHANNELS)[:, :width]
    Xb = Xh.reshape(len(X), -1).copy()
    Xb[0, 0] = np.nan
    Xb[1, ::CHANNELS] = np.nan  # electrode 0 missing in every frame
    Xb[3] = Xb[3, :CHANNELS].tolist() * width  # no change: R = 0
    ours = run_graph(graph, Xb)
    ref = clf.decision_function(Xb.astype(np.float32))
    np.testing.assert_allclose(ours, ref, rtol=1e-6, atol=1e-5)
    report = check_parity(clf, graph, Xb)
    assert (True, 1.0) == (report["passed"], report["agreement"])


def test_twist_graph_names_rotational_second() -> None:
    """The twist rule's decision: rotational where score >= 0, the linear class below."""
    X, y = twist_windows()
    clf = SlipTwistClassifier(n_channels=CHANNELS).fit(X, y)
    graph = export(clf, n_frames=WIDTH)
    Xh = twist_windows(seed=1)[0]
    decided = np.where(run_graph(graph, Xh) >= 0, graph.classes[1], graph.classes[0])
    assert ("linear", "rotational") == graph.classes
    assert clf.predict(Xh).tolist() == decided.tolist()


def test_importing_slipkit_export_registers_both_rules() -> None:
    """slipkit.export's import registers the energy and twist exporters (the compare path)."""
    from slipkit.export.registry import exporter_for

    assert (export_electrode_energy, export_slip_twist) == (
        exporter_for(ElectrodeEnergyClassifier),
        exporter_for(SlipTwistClassifier),
    )


def test_window_length_is_required_and_checked() -> None:
    """Without n_frames, or with a length the rule cannot score, export is refused by name."""
    X, y = energy_windows()
    energy = ElectrodeEnergyClassifier(n_channels=CHANNELS).fit(X, y)
    twist = SlipTwistClassifier(n_channels=CHANNELS).fit(*twist_windows())
    with pytest.raises(ExportError, match="n_frames"):
        export_electrode_energy(energy)
    with pytest.raises(ExportError, match="n_frames must be a whole number >= 2"):
        export_electrode_energy(energy, n_frames=1)
    with pytest.raises(ExportError, match="n_frames must be a whole number >= 1"):
        export_slip_twist(twist, n_frames=0)


# -- through slipkit train / slipkit export -------------------------------------------

RATE_HZ = 50.0
N_FRAMES = 80
STREAM_CHANNELS = ("e1", "e2", "e3", "e4")


def _dataset(classes: dict[str, list[float]]) -> Dataset:
    """3 objects x 2 trials per class of 80 frames at 50 Hz, each class a drift pattern."""
    rng = np.random.default_rng(0)
    trials = []
    for cls, drift in classes.items():
        for obj in range(3):
            for rep in range(2):
                t = np.arange(N_FRAMES) / RATE_HZ
                x = 1000.0 + np.outer(t, drift) * 40.0
                x += rng.normal(scale=0.2, size=x.shape)
                table = pd.DataFrame(x, columns=list(STREAM_CHANNELS))
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
                STREAM_CHANNELS,
                dict.fromkeys(STREAM_CHANNELS, "counts"),
                rate_hz=RATE_HZ,
            )
        },
        labels={"slip_class": LabelSpec("slip_class", classes=tuple(classes))},
        groups=("object",),
        provenance={"scene": "unit-test"},
        name="window-rules",
    )


def _compose(name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


def _train_and_export(
    tmp_path: Path, classes: dict[str, list[float]], detector: str, split: list[str]
) -> tuple[dict, Path]:
    from slipkit.export.commands import export_main
    from slipkit.train.commands import train_main

    save_dataset(_dataset(classes), tmp_path / "data")
    train_main(
        _compose(
            "train",
            [
                f"dataset.path={tmp_path / 'data'}",
                "task=window_slip_type",
                "task.window=6",
                "task.hop=1",
                "task.onset_label=null",
                *split,
                "task.first_frame_control=false",
                "task.dynamics=null",
                f"detector={detector}",
                f"detector.n_channels={len(STREAM_CHANNELS)}",
                f"run_dir={tmp_path / 'run'}",
            ],
        )
    )
    out = tmp_path / "bundle"
    export_main(
        _compose(
            "export",
            [f"run={tmp_path / 'run'}", f"out={out}", "choose_session=false"],
        )
    )
    return json.loads((out / "manifest.json").read_text()), out


def test_energy_run_exports_a_bundle_whose_slip_class_is_the_motion_class(
    tmp_path: Path,
) -> None:
    """slipkit train + export: the energy bundle decides t vs its motion class and replays."""
    m, out = _train_and_export(
        tmp_path,
        {"n": [1, 0, 0, 0], "e": [0, 1, 0, 0], "t": [0, 0, 0, 0]},
        "electrode_energy",
        # as dos_real: k-fold by object, then refit on every trial, so parity runs on
        # training windows, one of which sits on the ROC threshold (a float32 flip
        # within the parity rule's 0.1 %: 1350 windows here)
        ["task.split=group", "task.folds=3"],
    )
    d = m["decision"]
    assert ("threshold", "t", d["classes"][1], False) == (
        d["rule"],
        d["classes"][0],
        d["positive"],
        d["strict"],
    )
    assert [1, 6 * len(STREAM_CHANNELS)] == m["inputs"][0]["shape"]
    replay = np.load(out / "replay.npz")
    summary = (
        StreamLoop(load_bundle(out))
        .run(ReplaySource(replay["frames"], replay["timestamps"]))
        .summary()
    )
    assert 0 < summary["slip_decisions"] < summary["decisions"]


def test_twist_run_exports_a_bundle_that_flags_rotational_slip(tmp_path: Path) -> None:
    """slipkit train + export: the twist bundle is a linear / rotational threshold rule, held out."""
    m, out = _train_and_export(
        tmp_path,
        {"linear": [1, 0.8, 0.5, 0.3], "rotational": [1, 0.6, -0.7, -0.9]},
        "slip_twist",
        ["task.split=trial", "task.test_size=0.5"],  # as biotac_slip_type: held out
    )
    d = m["decision"]
    assert ("threshold", ["linear", "rotational"], "rotational", True) == (
        d["rule"],
        d["classes"],
        d["positive"],
        m["training"]["held_out"],
    )
    replay = np.load(out / "replay.npz")
    summary = (
        StreamLoop(load_bundle(out))
        .run(ReplaySource(replay["frames"], replay["timestamps"]))
        .summary()
    )
    assert 0 < summary["slip_decisions"] < summary["decisions"]
