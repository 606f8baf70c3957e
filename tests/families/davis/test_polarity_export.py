"""DAVIS deploys: the polarity rule's graph, event frames, and train -> export -> slipkit-run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.export import export
from slipkit.export.parity import run_graph
from slipkit.families.davis.deploy import davis_event_frames
from slipkit.families.davis.export.polarity import DavisAreaRule
from slipkit.families.davis.polarity import DavisPolarity, classify


def _compose(name: str, overrides: list[str]) -> DictConfig:
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    GlobalHydra.instance().clear()
    return cfg


def test_rule_graph_decides_as_the_polarity_rule() -> None:
    """The graph's score is > 0 exactly where the paper's rule says slip, on every small area pair."""
    pos, neg = np.meshgrid(np.arange(40.0), np.arange(40.0))
    areas = np.column_stack([pos.ravel(), neg.ravel()])
    graph = export(DavisAreaRule().fit())
    score = run_graph(graph, areas).ravel()
    expected = classify(areas[:, 0], areas[:, 1]) == 2
    assert expected.tolist() == (score > 0).tolist()


def test_event_frames_hold_the_detectors_events() -> None:
    """Event frames count each event in its 10 ms frame and polarity, frames 0 to the last one's."""
    ev = np.array(
        [[0.001, 3, 2, 1], [0.004, 3, 2, 1], [0.012, 0, 1, -1], [0.035, 4, 0, 1]]
    )
    frames, times = davis_event_frames(ev, frame_s=0.01, height_px=3, width_px=5)
    expected = np.zeros((4, 2, 3, 5))
    expected[0, 0, 2, 3] = 2
    expected[1, 1, 1, 0] = 1
    expected[3, 0, 0, 4] = 1
    assert expected.tolist() == frames.tolist()
    assert [0.01, 0.02, 0.03, 0.04] == np.round(times, 9).tolist()


def test_op_areas_equal_detector_on_simulated_frames() -> None:
    """On simulated release trials, the runtime op's areas equal DavisPolarity.frames per frame."""
    from slipkit.runtime.preprocessing import Pipeline
    from slipkit.sim.commands import build_scene

    cfg = _compose("simulate", ["scene=davis_release"])
    ds = build_scene(cfg.scene).simulate(1, seed=3)
    det = DavisPolarity().fit(np.empty((0, 4)))
    ev = next(iter(ds)).streams["events"][["t", "x", "y", "polarity"]].to_numpy()
    frames, _ = davis_event_frames(ev, frame_s=0.01, height_px=180, width_px=190)
    step = {
        "op": "davis_areas",
        "opening_px": det.opening_px,
        "opening_shape": det.opening_shape,
        "closing_px": det.closing_px,
        "min_area_px": det.min_area_px,
    }
    pipe = Pipeline([step], (1, 2, 180, 190), "manifest.json")
    expected = det.frames(ev)[["pos_area_px", "neg_area_px"]].to_numpy(float)
    actual = np.stack([pipe(f[None])[0].copy() for f in frames])
    assert expected.tolist() == actual.tolist()
    assert expected[:, 0].max() > 0  # the release is seen


def test_train_export_replay_decides_as_the_detector(tmp_path: Path) -> None:
    """davis_release run -> slipkit export -> slipkit-run on replay.npz: the detector's slip frames."""
    from slipkit.export.commands import export_main
    from slipkit.families.davis.polarity import clean_frame
    from slipkit.runtime.cli import main
    from slipkit.train.commands import train_main

    run = tmp_path / "run"
    train_main(
        _compose(
            "train",
            ["experiment=davis_release", "dataset.n_trials=4", f"run_dir={run}"],
        )
    )
    out = tmp_path / "bundle"
    export_main(
        _compose("export", [f"run={run}", f"out={out}", "choose_session=false"])
    )
    raw = json.loads((out / "manifest.json").read_text())
    report = tmp_path / "report.json"
    with pytest.raises(SystemExit) as done:
        main([str(out), "--replay", str(out / "replay.npz"), "--json", str(report)])
    summary = json.loads(report.read_text())
    frames = np.load(out / "replay.npz")["frames"]
    det = DavisPolarity()
    kw = {k: getattr(det, k) for k in raw["preprocessing"][0] if k != "op"}
    areas = np.array(
        [[clean_frame(f[i] > 0, **kw).sum() for i in (0, 1)] for f in frames]
    )
    expected_slip = int((classify(areas[:, 0], areas[:, 1]) == 2).sum())
    assert [[2, 180, 190], "davis_areas", 1.0, 0] == [
        raw["frame"]["shape"],
        raw["preprocessing"][0]["op"],
        raw["training"]["parity"]["agreement"],
        done.value.code,
    ]
    assert [len(frames), expected_slip] == [
        summary["decisions"],
        summary["slip_decisions"],
    ]
    assert expected_slip > 0
