"""Grasp stability (BTS3v2): split by object, selection on training objects only."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from sklearn.compose import ColumnTransformer
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.svm import SVC

import slipkit
from slipkit.data.dataset import Dataset
from slipkit.data.importers.bts3v2 import CHANNELS, ORIENTATIONS, read_bts3v2
from slipkit.data.io import save_dataset
from slipkit.errors import SlipkitError
from slipkit.families.biotac.grasp_task import GraspFeatures, GraspStability
from slipkit.train.commands import _overlap_line, evaluate_main, train_main

#: Per-orientation electrode baselines (counts): the shift the task must cope with.
BASELINE = {"palm_down": 2800.0, "palm_side": 2950.0, "palm_45": 3150.0}


def write_synthetic_bts3v2(
    folder: Path, n_objects: int = 12, seed: int = 0, *, test: bool = False
) -> Path:
    """BTS3v2 layout: slipped when electrodes 0-5 of the thumb read low, plus an
    orientation-dependent baseline (``test``: the published test files, of objects
    ``new0..``)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(exist_ok=True)
    for orientation in ORIENTATIONS:
        rows = []
        for k in range(n_objects):
            for _ in range(10):
                e = BASELINE[orientation] + rng.normal(0.0, 30.0, 72)
                slipped = int(rng.random() < 0.5)
                e[48:54] -= 0.0 if slipped else 150.0
                rows.append([f"{'new' if test else 'obj'}{k}", slipped, *e.round(0)])
        pd.DataFrame(rows, columns=["object", "slipped", *CHANNELS]).to_csv(
            folder / f"bts3v2_{orientation}{'_test' if test else ''}.csv", index=False
        )
    return folder


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    return read_bts3v2(write_synthetic_bts3v2(tmp_path_factory.mktemp("d") / "bts"))


def _task(**kw: object) -> GraspStability:
    base: dict[str, object] = {
        "model_name": "logreg",
        "candidates": {"svm": SVC()},
        "n_trials": 2,
        "cv": 3,
        "spaces": {
            "logreg": {"C": [0.01, 10.0, "log"], "normalise": {"choices": ["none"]}},
            "svm": {"C": [0.1, 10.0, "log"]},
        },
    }
    return GraspStability(**{**base, **kw})  # type: ignore[arg-type]


def _relabel(dataset: Dataset, ids: list[str]) -> Dataset:
    """``dataset`` with the classes of ``ids`` swapped (wrong labels)."""
    trials = dataset.trials.copy()
    rows = trials["trial_id"].isin(ids)
    trials.loc[rows, "slip_class"] = np.where(
        trials.loc[rows, "slip_class"] == "stable", "slipped", "stable"
    )
    return _with_trials(dataset, trials)


def _with_trials(dataset: Dataset, trials: pd.DataFrame) -> Dataset:
    """``dataset`` with another trials table."""
    return Dataset(
        sensor=dataset.sensor,
        streams=dataset.streams,
        trials=trials,
        tables=dataset.tables,
        labels=dataset.labels,
        groups=dataset.groups,
        provenance=dataset.provenance,
        name=dataset.name,
    )


def test_grasp_split_keeps_objects_apart_and_reports_the_controls(
    synthetic: Dataset, tmp_path: Path
) -> None:
    """Test objects never reach training; metrics hold per-orientation and majority scores."""
    m = _task().fit(LogisticRegression(), synthetic, seed=0, out=tmp_path).metrics
    sp = m["split"]
    assert set() == set(sp["train_objects"]) & set(sp["test_objects"])
    assert 360 == sp["n_train"] + sp["n_test"]
    assert set(ORIENTATIONS) == set(m["test"]["per_orientation"])
    assert 0.5 == m["majority_control_test"]["balanced_accuracy"]
    assert m["test"]["balanced_accuracy"] > 0.9  # the synthetic rule is easy
    assert m["selection"]["best"]["model"] in {"logreg", "svm"}
    assert 4 == len(m["selection"]["candidates"])
    assert [
        "none",
        "per_grasp",
        "shape",
        "orientation_feature",
        "per_orientation",
    ] == list(m["normalisation_at_best"])
    assert {"scores.csv", "normalisation.csv"} <= {p.name for p in tmp_path.iterdir()}


def test_grasp_report_puts_the_controls_beside_each_orientation(
    synthetic: Dataset, tmp_path: Path
) -> None:
    """Test scores, majority, orientation-only and plain logistic regression, per orientation."""
    m = _task().fit(LogisticRegression(), synthetic, seed=0, out=tmp_path).metrics
    controls = m["controls_test"]
    assert {"majority", "orientation_only", "plain_logreg"} == set(controls)
    for scored in (m["test"], *controls.values()):
        assert set(ORIENTATIONS) == set(scored["per_orientation"])
    # a constant answer per orientation is at chance in every orientation
    assert [0.5, 0.5, 0.5] == [
        controls["orientation_only"]["per_orientation"][o]["balanced_accuracy"]
        for o in ORIENTATIONS
    ]
    assert (
        controls["plain_logreg"]["balanced_accuracy"] > 0.9
    )  # the synthetic rule is easy
    table = pd.read_csv(tmp_path / "scores.csv")
    assert 16 == len(table)  # 4 scored x (all + 3 orientations)
    assert {"test", "majority", "orientation_only", "plain_logreg"} == set(
        table["scored"]
    )
    assert set(ORIENTATIONS) == set(m["validation"]["per_orientation"])


def test_grasp_test_labels_cannot_change_the_selection_or_the_objective(
    synthetic: Dataset, tmp_path: Path
) -> None:
    """Swapping the labels of the held-out objects changes test scores, not the choice."""
    task = _task()
    clean = task.fit(LogisticRegression(), synthetic, seed=0, out=tmp_path).metrics
    test_ids = synthetic.trials.loc[
        synthetic.trials["object"].isin(clean["split"]["test_objects"]), "trial_id"
    ].tolist()
    bad = task.fit(
        LogisticRegression(), _relabel(synthetic, test_ids), seed=0, out=tmp_path
    ).metrics
    assert clean["test"]["accuracy"] != bad["test"]["accuracy"]
    assert clean["selection"] == bad["selection"]
    assert task.objective_value(clean) == task.objective_value(bad)


def test_per_orientation_features_remove_the_orientation_baseline(
    synthetic: Dataset,
) -> None:
    """per_orientation standardises each orientation to zero mean; per_grasp zeroes each pad's mean."""
    X, _, _ = GraspStability().arrays(synthetic)
    per_o = GraspFeatures(normalise="per_orientation").fit(X).transform(X)
    onehot = X[:, 72:] > 0.5
    for k in range(3):
        assert np.allclose(0.0, per_o[onehot[:, k]].mean(axis=0), atol=1e-9)
    per_g = GraspFeatures(normalise="per_grasp").fit(X).transform(X)
    assert np.allclose(0.0, per_g.reshape(len(X), 3, 24).mean(axis=2), atol=1e-9)
    with_o = GraspFeatures(normalise="orientation_feature").fit(X).transform(X)
    assert (len(X), 75) == with_o.shape


def write_orientation_trap(folder: Path, n_objects: int = 12, seed: int = 0) -> Path:
    """BTS3v2 layout where electrodes 0-5 decide stability when the palm is down or at
    45 deg but are noise with the palm to the side; electrodes 30-35 are a noisier
    (75 %) cue in every orientation; one baseline for all orientations."""
    rng = np.random.default_rng(seed)
    folder.mkdir()
    for orientation in ORIENTATIONS:
        rows = []
        for k in range(n_objects):
            for _ in range(20):
                e = 2800.0 + rng.normal(0.0, 30.0, 72)
                slipped = int(rng.random() < 0.5)
                if orientation != "palm_side":
                    e[0:6] -= 0.0 if slipped else 150.0
                cue = slipped if rng.random() < 0.75 else 1 - slipped
                e[30:36] -= 0.0 if cue else 150.0
                rows.append([f"obj{k}", slipped, *e.round(0)])
        pd.DataFrame(rows, columns=["object", "slipped", *CHANNELS]).to_csv(
            folder / f"bts3v2_{orientation}.csv", index=False
        )
    return folder


def _only(columns: list[int]) -> Pipeline:
    """Logistic regression on some electrode columns only."""
    return make_pipeline(
        ColumnTransformer([("pick", "passthrough", columns)]), LogisticRegression()
    )


def test_worst_orientation_selection_never_picks_a_model_that_fails_one_orientation(
    tmp_path: Path,
) -> None:
    """Pooled scoring picks the cue that is chance with the palm side; worst-orientation does not."""
    trap = read_bts3v2(write_orientation_trap(tmp_path / "bts"))
    chosen = {}
    for scoring in ("balanced_accuracy", "worst_orientation_balanced_accuracy"):
        task = GraspStability(
            model_name="sharp",
            candidates={"steady": _only(list(range(30, 36)))},
            spaces={},
            cv=3,
            scoring=scoring,
        )
        m = task.fit(_only(list(range(6))), trap, seed=0, out=tmp_path).metrics
        chosen[scoring] = m["selection"]["best"]["model"]
    assert {
        "balanced_accuracy": "sharp",
        "worst_orientation_balanced_accuracy": "steady",
    } == chosen


def test_grasp_task_refuses_an_unknown_scoring(
    synthetic: Dataset, tmp_path: Path
) -> None:
    """An unknown task.scoring is refused in one line naming the option and the value."""
    with pytest.raises(SlipkitError, match=r"task\.scoring: unknown scorer 'worst'"):
        _task(scoring="worst").fit(
            LogisticRegression(), synthetic, seed=0, out=tmp_path
        )


def test_shape_features_ignore_a_pad_offset_and_gain(synthetic: Dataset) -> None:
    """shape gives the same features when a finger pad's readings are shifted and scaled."""
    X, _, _ = GraspStability().arrays(synthetic)
    moved = X.copy()
    for finger, (gain, offset) in enumerate([(1.3, 250.0), (0.8, -400.0), (1.0, 90.0)]):
        pad = slice(24 * finger, 24 * (finger + 1))
        moved[:, pad] = gain * moved[:, pad] + offset
    features = GraspFeatures(normalise="shape").fit(X)
    # equal up to SHAPE_EPS (1 count^2 beside a pad variance of ~900 counts^2 here)
    assert np.allclose(features.transform(X), features.transform(moved), atol=5e-3)
    raw = GraspFeatures(normalise="none").fit(X)
    assert not np.allclose(raw.transform(X), raw.transform(moved), atol=5e-3)


def test_grasp_task_names_a_missing_column(synthetic: Dataset, tmp_path: Path) -> None:
    """A group column the dataset lacks is refused, naming it."""
    with pytest.raises(SlipkitError, match="'grip'"):
        GraspStability(group="grip").fit(
            LogisticRegression(), synthetic, seed=0, out=tmp_path
        )


def test_published_test_files_are_the_test_set_and_never_train(
    tmp_path: Path,
) -> None:
    """With the published test files imported, they are the test set (auto); with
    split=objects they are left out; one set alone is split by object; published
    without both sets, or an object in both sets, is refused."""
    raw = write_synthetic_bts3v2(tmp_path / "bts", n_objects=6)
    write_synthetic_bts3v2(raw, n_objects=3, seed=1, test=True)
    both = read_bts3v2(raw)
    m = _task(cv=2).fit(LogisticRegression(), both, seed=0, out=tmp_path).metrics
    sp = m["split"]
    assert "published test files" == sp["test_set"]
    assert ["new0", "new1", "new2"] == sp["test_objects"]
    assert (180, 90) == (sp["n_train"], sp["n_test"])
    # the test files' labels change the test scores only, never the selection
    test_ids = both.trials.loc[both.trials["published_split"] == "test", "trial_id"]
    bad = (
        _task(cv=2)
        .fit(
            LogisticRegression(),
            _relabel(both, test_ids.tolist()),
            seed=0,
            out=tmp_path,
        )
        .metrics
    )
    assert m["selection"] == bad["selection"]
    assert m["test"]["accuracy"] != bad["test"]["accuracy"]
    alone = read_bts3v2(raw / "bts3v2_palm_down.csv")
    m_obj = (
        _task(cv=2, split="objects")
        .fit(LogisticRegression(), both, seed=0, out=tmp_path)
        .metrics["split"]
    )
    assert "held-out objects" == m_obj["test_set"]
    assert not {"new0", "new1", "new2"} & set(
        m_obj["train_objects"] + m_obj["test_objects"]
    )
    only_test = both.subset(test_ids.tolist())
    m_test = _task(cv=2).fit(LogisticRegression(), only_test, seed=0, out=tmp_path)
    assert "held-out objects" == m_test.metrics["split"]["test_set"]
    with pytest.raises(SlipkitError, match=r"task\.split=published: .* needs trials"):
        _task(split="published").fit(LogisticRegression(), alone, seed=0, out=tmp_path)
    trials = both.trials.copy()
    trials.loc[trials["trial_id"] == "palm_45_test/0000", "object"] = "obj0"
    with pytest.raises(SlipkitError, match=r"objects \['obj0'\] are in both"):
        _task().fit(
            LogisticRegression(), _with_trials(both, trials), seed=0, out=tmp_path
        )


def test_train_bts3v2_stability_end_to_end_on_a_synthetic_recording(
    tmp_path: Path,
) -> None:
    """slipkit train experiment=bts3v2_stability reads a BTS3v2 folder; objective = validation."""
    raw = write_synthetic_bts3v2(tmp_path / "bts3v2", n_objects=8)
    run = tmp_path / "run"
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        cfg = compose(
            config_name="train",
            overrides=[
                "experiment=bts3v2_stability",
                f"dataset.raw={raw}",
                f"run_dir={run}",
                "task.n_trials=1",
                "task.cv=2",
                "model.max_iter=20",
            ],
        )
    objective = train_main(cfg)
    info = json.loads((run / "run.json").read_text())
    metrics = json.loads((run / "metrics.json").read_text())
    assert "validation.worst_orientation_balanced_accuracy" == info["objective"]["name"]
    assert metrics["validation"]["worst_orientation_balanced_accuracy"] == objective
    assert {"mlp"} == set(metrics["selection"]["by_model"])
    assert metrics["params"]["normalise"] in {"per_grasp", "shape"}
    assert 2 == len(metrics["split"]["test_objects"])  # 24 % of 8 objects
    # slipkit evaluate on a recording of other objects: overall, per orientation, worst
    other = write_synthetic_bts3v2(tmp_path / "other_raw", n_objects=3, seed=5)
    folder = save_dataset(read_bts3v2(other), tmp_path / "other")
    payload = _evaluate(run, folder, "other")
    assert not payload["dataset"]["held_out_only"]
    scores = payload["test"]
    assert 90 == scores["n"]
    assert set(ORIENTATIONS) == set(scores["per_orientation"])
    assert (
        min(m["balanced_accuracy"] for m in scores["per_orientation"].values())
        == scores["worst_orientation_balanced_accuracy"]
    )
    # beside its training files, only the published test files are scored
    write_synthetic_bts3v2(other, n_objects=2, seed=6, test=True)
    both = save_dataset(read_bts3v2(other), tmp_path / "both")
    payload = _evaluate(run, both, "both")
    assert 60 == payload["test"]["n"]
    # never trained on, whatever the run: no warning even on the run's own dataset
    assert payload["dataset"]["held_out_only"]
    assert "" == _overlap_line({**payload["dataset"], "seen_in_training": True})
    assert _overlap_line(
        {**payload["dataset"], "held_out_only": False, "seen_in_training": True}
    )


def _evaluate(run: Path, dataset: Path, name: str) -> dict[str, Any]:
    """``slipkit evaluate run=<run> dataset=<dataset>``: its metrics.json."""
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        cfg = compose(
            config_name="evaluate",
            overrides=[f"run={run}", f"dataset={dataset}", f"name={name}"],
        )
    payload: dict[str, Any] = json.loads(evaluate_main(cfg).read_text())
    return payload


@pytest.mark.realdata
@pytest.mark.slow
def test_bts3v2_on_the_real_recordings_beats_75_percent(
    shared_data: Path, tmp_path: Path
) -> None:
    """On held-out real objects the selected model passes 75 % accuracy (majority ~50 %)."""
    folder = shared_data / "bts3v2"
    if not folder.is_dir():
        pytest.skip(f"{folder} not present")
    task = _task(cv=3, n_trials=2)
    m = task.fit(
        LogisticRegression(), read_bts3v2(folder), seed=0, out=tmp_path
    ).metrics
    assert m["test"]["accuracy"] >= 0.75
    assert m["majority_control_test"]["accuracy"] < 0.6


@pytest.mark.parametrize(
    "mode", ["none", "per_grasp", "shape", "orientation_feature", "per_orientation"]
)
def test_grasp_pipeline_exports_to_onnx_with_parity(
    synthetic: Dataset, mode: str
) -> None:
    """Every orientation handling exports through skl2onnx and matches scikit-learn."""
    from slipkit.export import export
    from slipkit.export.parity import check_parity
    from slipkit.families.biotac.grasp_task import grasp_pipeline

    X, y, _ = GraspStability().arrays(synthetic)
    pipe = grasp_pipeline(SVC()).set_params(prep__normalise=mode).fit(X[::2], y[::2])
    report = check_parity(pipe, export(pipe), X[1::2])
    assert (True, "decision_function") == (report["passed"], export(pipe).score_method)
