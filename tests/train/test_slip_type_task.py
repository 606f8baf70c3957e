"""WindowClassification: splits, vote, time table, train/evaluate end to end, real DoS data."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from hydra import compose, initialize_config_dir
from sklearn.dummy import DummyClassifier
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from tests.strategies import make_dataset

import slipkit
from slipkit.compare.adapters import _window_controls
from slipkit.compare.report import CONTROLS, markdown_table
from slipkit.data import save_dataset
from slipkit.demo import _controls_section
from slipkit.errors import SlipkitError
from slipkit.models.selection import CandidateSearch
from slipkit.models.window import WindowMLP
from slipkit.models.window_features import WindowStatistics
from slipkit.sim.commands import build_scene
from slipkit.train.commands import evaluate_main, train_main
from slipkit.train.tasks.slip_type import (
    WindowClassification,
    accuracy_vs_time,
    majority_vote,
)

torch.set_num_threads(1)


def tiny_task(**kw) -> WindowClassification:
    """A window task on the 'force' stream of tests.strategies.make_dataset (300 Hz)."""
    params = {
        "stream": "force",
        "window": 20,
        "hop": 10,
        "onset_label": None,
        "sweep": [],
        "dynamics": None,
        "first_frame_control": False,
    }
    params.update(kw)
    return WindowClassification(**params)


@pytest.mark.parametrize(
    ("split", "folds"), [("trial", None), ("trial", 3), ("group", None), ("group", 3)]
)
def test_windows_of_one_trial_never_sit_on_both_sides(split, folds):
    """Every fold's train and test trials (and objects, by group) are disjoint."""
    ds = make_dataset(n_trials=12, n_frames=60, n_objects=4, with_events=False)
    task = tiny_task(split=split, folds=folds, test_size=0.25)
    splits = task.splits(ds, seed=0)
    assert (folds or 1) == len(splits)
    objects = ds.trials.set_index("trial_id")["object"]
    for train, test in splits:
        w_train = task.windows(ds.subset(train), 20, "raw", span=None)
        w_test = task.windows(ds.subset(test), 20, "raw", span=None)
        assert set() == set(w_train.trial) & set(w_test.trial)
        if split == "group":
            assert set() == set(objects[list(train)]) & set(objects[list(test)])
    if folds:
        tested = sorted(t for _, te in splits for t in te)
        assert sorted(ds.trial_ids) == tested


def test_accuracy_vs_time_has_one_row_per_bin_and_a_column_per_model():
    """Bins of 0.1 s from -0.2 to 0.3 s: 6 rows; columns t, n, one accuracy per model."""
    t = np.repeat(np.arange(-0.2, 0.31, 0.1), 3)
    correct = {
        "model": np.tile([True, True, False], 6),
        "first_frame": np.ones(18, bool),
    }
    table = accuracy_vs_time(t, correct, 0.1)
    assert ["t_rel_s", "n_windows", "accuracy_model", "accuracy_first_frame"] == list(
        table.columns
    )
    assert [-0.2, -0.1, 0.0, 0.1, 0.2, 0.3] == table["t_rel_s"].tolist()
    assert [3] * 6 == table["n_windows"].tolist()
    np.testing.assert_allclose(np.full(6, 2 / 3), table["accuracy_model"])


def test_majority_vote_counts_windows_and_breaks_ties_by_probability():
    """Trial a: 2 of 3 windows 'x' -> x; trial b: a 1-1 tie goes to the surer class."""
    trial = np.array(["a", "a", "a", "b", "b"])
    pred = np.array(["x", "x", "y", "x", "y"])
    proba = np.array([[0.9, 0.1], [0.8, 0.2], [0.4, 0.6], [0.55, 0.45], [0.1, 0.9]])
    votes = majority_vote(trial, pred, proba, ["x", "y"])
    assert ["x", "y"] == votes["pred"].tolist()
    assert [3, 2] == votes["n_windows"].tolist()


def test_bad_config_and_missing_stream_are_clear_errors():
    """An unknown split, unit or stream names the field."""
    with pytest.raises(SlipkitError, match="split"):
        tiny_task(split="random")
    with pytest.raises(SlipkitError, match="unit"):
        tiny_task(unit="s")
    ds = make_dataset(n_trials=4, n_frames=30, with_events=False)
    with pytest.raises(SlipkitError, match="no stream 'electrodes'"):
        tiny_task(stream="electrodes").windows(ds, 5, "raw", span=None)
    with pytest.raises(SlipkitError, match="no windows of 40 frames"):
        tiny_task().windows(ds, 40, "raw", span=None)


def compose_train(tmp_path: Path, *overrides: str):
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        return compose(
            config_name="train",
            overrides=[
                "experiment=biotac_slip_type",
                f"run_dir={tmp_path / 'run'}",
                *overrides,
            ],
        )


def test_train_and_evaluate_end_to_end_on_the_simulated_lift(tmp_path, capsys):
    """A shrunk biotac_slip_type run writes metrics, the two tables and plots, then evaluates."""
    cfg = compose_train(
        tmp_path,
        "dataset.n_trials=16",
        "task.window=30",
        "task.hop=6",
        "task.sweep=[10,30]",
        "model.max_epochs=4",
        "+task.compare.cnn.max_epochs=2",
    )
    objective = train_main(cfg)
    run = tmp_path / "run"
    metrics = json.loads((run / "metrics.json").read_text())
    assert objective == pytest.approx(metrics["validation"]["balanced_accuracy"])
    assert 0.0 <= metrics["accuracy"] <= 1.0
    assert {"first_frame", "dynamics", "majority"} == set(metrics["controls"])
    assert ["cnn"] == list(metrics["compare"])
    assert [10, 30] == [r["frames"] for r in metrics["accuracy_vs_width"]]
    for name in ("accuracy_vs_time", "accuracy_vs_width"):
        assert (run / f"{name}.png").stat().st_size > 0
    curve = pd.read_csv(run / "accuracy_vs_time.csv")
    assert curve["t_rel_s"].between(-0.2 - 1e-9, 0.3 + 1e-9).all()
    printed = capsys.readouterr().out
    assert "per window" in printed
    assert "majority class" in printed
    assert str(run) == printed.strip().splitlines()[-1]
    row = _window_controls(metrics)
    assert (
        metrics["controls"]["dynamics"]["window"]["accuracy"]
        == row["dynamics_accuracy"]
    )
    assert metrics["sequence"]["balanced_accuracy"] == row["sequence_balanced_accuracy"]
    table = markdown_table(pd.DataFrame([{"estimator": "mlp", **row}]), CONTROLS)
    assert "| estimator | sequence acc | sequence bal. | first frame only |" in table
    demo = _controls_section({"biotac_slip_type": {"estimator": "mlp", **row}})
    assert "| biotac_slip_type | `mlp` | " in "\n".join(demo)

    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        scfg = compose(config_name="simulate", overrides=["scene=biotac_lift_slip"])
    unseen = build_scene(scfg.scene).simulate(4, 99, progress=False)
    folder = save_dataset(unseen, tmp_path / "unseen")
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        ecfg = compose(
            config_name="evaluate",
            overrides=[f"run={run}", f"dataset={folder}", "name=unseen"],
        )
    out = evaluate_main(ecfg)
    scores = json.loads(out.read_text())
    assert 4 == scores["dataset"]["n_trials"]
    assert 4 == scores["sequence"]["n"]
    assert 0.0 <= scores["accuracy"] <= 1.0


@pytest.mark.realdata
def test_dos_direction_on_unseen_objects_with_its_controls(shared_data, tmp_path):
    """BioTacSP-DoS, 7 directions, 2 unseen objects: scored per window and sequence, controls beside."""
    from slipkit.data.importers.biotacsp_dos import read_biotacsp_dos

    ds = read_biotacsp_dos(shared_data / "biotacsp-dos")
    task = WindowClassification(
        label="slip_class",
        window=50,
        hop=200,
        unit="ms",
        onset_label=None,
        dynamics="trial",
        split="group",
        test_size=0.25,
    )
    model = WindowMLP(max_epochs=15, lr=0.01, random_state=0)
    result = task.fit(model, ds, seed=0, out=tmp_path)
    m = result.metrics
    (test_objects,) = m["split"]["test_groups"]
    assert 2 == len(test_objects)
    train_objects = set(ds.trials["object"]) - set(test_objects)
    assert 6 == len(train_objects)
    assert 5 == m["window"]["frames"]
    assert ["n", "e", "s", "w", "cw", "aw", "t"] == m["classes"]
    # The README's caution, measured: the static contact alone predicts the direction
    # far above chance (1/7) on objects never seen.
    assert m["first_frame_accuracy"] > 2 * m["chance"]
    assert 0.0 <= m["dynamics_accuracy"] <= 1.0
    assert 0.0 <= m["sequence_accuracy"] <= 1.0


def search_model() -> CandidateSearch:
    """Statistics + logistic regression (two C) against the majority class, no progress bar."""
    stats_lr = make_pipeline(
        WindowStatistics(n_channels=3), StandardScaler(), LogisticRegression()
    )
    return CandidateSearch(
        candidates={"majority": DummyClassifier(), "stats_lr": stats_lr},
        grids={"stats_lr": {"logisticregression__C": [0.01, 1.0]}},
        verbose=False,
    )


def test_selection_is_per_fold_and_test_labels_cannot_move_it(tmp_path):
    """Fold 0's choice is made on its training objects: swapping its test labels leaves it alone."""
    ds = make_dataset(n_trials=18, n_frames=60, n_objects=3, with_events=False)
    task = tiny_task(split="group", folds=3)
    m = task.fit(search_model(), ds, seed=0, out=tmp_path).metrics
    sel = m["selection"]
    assert ("leave-one-object-out", "balanced_accuracy") == (sel["cv"], sel["scoring"])
    assert 3 == len(sel["candidates"]) == len(m["split"]["test"])
    assert [0, 1, 2] == [f["fold"] for f in sel["per_fold"]]
    assert 3 == sel["n_groups"]  # the saved model chose over every object
    test0 = list(m["split"]["test"][0])
    swapped = copy.deepcopy(ds)
    rows = swapped.trials["trial_id"].isin(test0)
    swapped.trials.loc[rows, "slip_class"] = swapped.trials.loc[rows, "slip_class"].map(
        {"linear": "rotational", "rotational": "linear"}
    )
    m2 = task.fit(search_model(), swapped, seed=0, out=tmp_path).metrics
    assert sel["per_fold"][0] == m2["selection"]["per_fold"][0]
    assert m["test"]["confusion"] != m2["test"]["confusion"]


@pytest.mark.realdata
@pytest.mark.slow  # ~15-30 s: leave-one-object-out selection over six objects
def test_dos_selection_by_unseen_objects_with_its_controls(shared_data, tmp_path):
    """BioTacSP-DoS, 200 ms statistics: selection on the 6 training objects, controls beside."""
    from slipkit.data.importers.biotacsp_dos import read_biotacsp_dos

    ds = read_biotacsp_dos(shared_data / "biotacsp-dos")
    task = WindowClassification(
        label="slip_class",
        window=200,
        hop=200,
        unit="ms",
        onset_label=None,
        dynamics="trial",
        split="group",
        test_size=0.25,
    )
    stats_lr = make_pipeline(
        WindowStatistics(n_channels=24), StandardScaler(), LogisticRegression(C=0.1)
    )
    model = CandidateSearch(
        candidates={"stats_lr": stats_lr},
        grids={"stats_lr": {"windowstatistics__subtract_first": [False, True]}},
        verbose=False,
    )
    m = task.fit(model, ds, seed=0, out=tmp_path).metrics
    (fold,) = m["selection"]["per_fold"]
    assert 6 == m["selection"]["n_groups"]  # one split: the saved model is the fold's
    assert fold["best_score"] > 2 * m["chance"]
    assert {"first_frame", "dynamics", "majority"} == set(m["controls"])
    assert m["accuracy"] > 3 * m["chance"]
    assert m["controls"]["majority"]["window"]["accuracy"] < 2 * m["chance"]
