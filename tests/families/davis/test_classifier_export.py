"""The learned DAVIS event-frame classifier exports: features and pipeline in one graph."""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from numpy.typing import NDArray
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.export import export
from slipkit.export.parity import check_parity, run_graph
from slipkit.families.davis.classifier import EventFrameClassifier
from slipkit.families.davis.deploy import davis_event_frames
from slipkit.families.davis.export.classifier import EventFrameScores, frame_counts


def _compose(name: str, overrides: list[str]) -> DictConfig:
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    GlobalHydra.instance().clear()
    return cfg


class Fitted(NamedTuple):
    """A classifier fitted on two hard-scene release trials and two held-out recordings."""

    clf: EventFrameClassifier
    held_out: list[NDArray[np.float64]]


@pytest.fixture(scope="module")
def fitted() -> Fitted:
    """Four simulated hard releases (seed 0): two to fit, two held out."""
    from slipkit.families.davis.task import DavisRelease
    from slipkit.sim.commands import build_scene

    ds = build_scene(_compose("simulate", ["scene=davis_release_hard"]).scene).simulate(
        4, seed=0
    )
    task = DavisRelease()
    train = ds.subset(ds.trial_ids[:2])
    X, seg = task._events_xy(train)
    onsets, ends = task._truth_spans(train)
    clf = EventFrameClassifier().fit(X, segments=seg, onsets=onsets, ends=ends)
    held = [
        tr.streams["events"]
        .sort_values("t", kind="stable")[["t", "x", "y", "polarity"]]
        .to_numpy(np.float64)
        for tr in ds.subset(ds.trial_ids[2:])
    ]
    return Fitted(clf, held)


def _frames(ev: NDArray[np.float64]) -> NDArray[np.float64]:
    frames, _ = davis_event_frames(ev, frame_s=0.02, height_px=180, width_px=190)
    return frames


def test_frame_counts_are_events_and_pixels_per_polarity() -> None:
    """Counts sum the frame per polarity; areas count the pixels that fired."""
    frames = np.zeros((1, 2, 3, 4))
    frames[0, 0, 1, 2] = 3
    frames[0, 0, 0, 0] = 1
    frames[0, 1, 2, 3] = 2
    counts, areas = frame_counts(frames)
    assert [[[4.0, 2.0]], [[2.0, 1.0]]] == [counts.tolist(), areas.tolist()]


def test_runtime_frame_features_equal_the_classifiers(fitted: Fitted) -> None:
    """Features of the runtime's 20 ms event frames equal frame_features on the events."""
    scores = EventFrameScores(classifier=fitted.clf).fit()
    for ev in fitted.held_out:
        _, expected = fitted.clf.frame_features(ev)
        assert expected.tolist() == scores.features(_frames(ev)).tolist()


def test_graph_decides_as_the_classifier_on_held_out_frames(fitted: Fitted) -> None:
    """The graph's logit matches the classifier's; slip frames equal its frames() rule."""
    graph = export(fitted.clf)
    scores = EventFrameScores(classifier=fitted.clf).fit()
    for ev in fitted.held_out:
        frames = _frames(ev)
        logit = run_graph(graph, frames).ravel()
        expected_slip = fitted.clf.frames(ev)["slip"].tolist()
        assert expected_slip == (logit >= 0).tolist()
        assert np.abs(logit - scores.decision_function(frames)).max() < 1e-5
        assert True == check_parity(scores, graph, frames)["passed"]  # noqa: E712
    assert True == any(fitted.clf.frames(ev)["slip"].any() for ev in fitted.held_out)  # noqa: E712


def test_graph_contract(fitted: Fitted) -> None:
    """One float32 event-frame input, a 1-D logit, classes 0/1, slip at score >= 0."""
    graph = export(EventFrameScores(classifier=fitted.clf).fit())
    assert [("batch", 2, 180, 190), ("0", "1"), 0.0, False, "decision_function"] == [
        graph.input_shape,
        graph.classes,
        graph.threshold,
        graph.strict,
        graph.score_method,
    ]


def test_unfitted_classifier_is_refused() -> None:
    """Exporting an unfitted classifier raises scikit-learn's NotFittedError."""
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        export(EventFrameClassifier())


def test_train_export_replay_decides_as_the_classifier(tmp_path: Path) -> None:
    """davis_release run of event_logreg -> slipkit export -> slipkit-run: the classifier's slip frames."""
    from slipkit.export.commands import export_main
    from slipkit.runtime.cli import main
    from slipkit.train.commands import train_main
    from slipkit.train.runs import read_run

    run = tmp_path / "run"
    train_main(
        _compose(
            "train",
            [
                "experiment=davis_release",
                "~detector",
                "model=davis_event_logreg",
                "dataset.n_trials=4",
                f"run_dir={run}",
            ],
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
    clf = read_run(run).model
    expected_slip = int(
        (EventFrameScores(classifier=clf).fit().decision_function(frames) >= 0).sum()
    )
    assert [[2, 180, 190], [], 50.0, 1.0, 0] == [
        raw["frame"]["shape"],
        raw["preprocessing"],
        raw["frame"]["rate_hz"],
        raw["training"]["parity"]["agreement"],
        done.value.code,
    ]
    assert [len(frames), expected_slip] == [
        summary["decisions"],
        summary["slip_decisions"],
    ]
    assert expected_slip > 0
