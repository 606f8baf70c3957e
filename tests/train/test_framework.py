"""The training framework's pieces: run folders, objectives, JSON, the in-run search."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from slipkit.errors import SlipkitError
from slipkit.train.runs import new_run_dir, read_run
from slipkit.train.search import optuna_search
from slipkit.train.task import Task, TaskResult, jsonable


class _Nothing(Task):
    objective = "test.score"

    def fit(self, model: Any, dataset: Any, *, seed: int, out: Path) -> TaskResult:
        return TaskResult(model, {})

    def evaluate(self, model: Any, dataset: Any, *, out: Path) -> dict[str, Any]:
        return {}


def test_objective_value_descends_dotted_keys() -> None:
    """The objective 'test.score' is read from metrics['test']['score']."""
    assert 0.5 == _Nothing().objective_value({"test": {"score": 0.5}})


def test_objective_value_missing_names_the_key() -> None:
    """A task whose metrics lack its objective says which key is missing."""
    with pytest.raises(KeyError, match=r"test\.score"):
        _Nothing().objective_value({"train": {}})


def test_jsonable_turns_numpy_and_nan_into_json() -> None:
    """numpy scalars/arrays become plain numbers and lists; NaN and inf become null."""
    value = {"a": np.float32(1.5), "b": np.arange(2), "c": math.nan, "d": (np.inf, 1)}
    expected = {"a": 1.5, "b": [0, 1], "c": None, "d": [None, 1]}
    assert expected == jsonable(value)
    json.dumps(jsonable(value), allow_nan=False)


def test_new_run_dir_never_reuses_a_folder(tmp_path: Path) -> None:
    """Two runs started in the same second get different folders."""
    first = new_run_dir(tmp_path, "exp")
    first.mkdir(parents=True)
    second = new_run_dir(tmp_path, "exp")
    assert first != second
    assert first.parent == second.parent


def test_new_run_dir_keeps_multirun_jobs_apart(tmp_path: Path) -> None:
    """A multirun job number is part of the folder name."""
    assert new_run_dir(tmp_path, "exp", job=3).name.endswith("_3")


_GOOD = {"config.yaml": "a: 1", "model.joblib": "x"}


@pytest.mark.parametrize(
    ("files", "message"),
    [
        ({}, "run.json is missing"),
        ({"run.json": "{", **_GOOD}, "not valid JSON"),
        ({"run.json": '{"format": "other"}', **_GOOD}, "field 'format'"),
        (
            {"run.json": '{"format": "slipkit-run", "schema_version": 99}', **_GOOD},
            "schema_version 99",
        ),
        (
            {
                "run.json": '{"format": "slipkit-run", "schema_version": 1, "model_sha256": "0"}',
                **_GOOD,
            },
            "does not match run.json",
        ),
    ],
)
def test_read_run_refuses_bad_folders(
    tmp_path: Path, files: dict[str, str], message: str
) -> None:
    """A folder that is not an intact run is refused with the file and field named."""
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    with pytest.raises(SlipkitError, match=message):
        read_run(tmp_path)


def test_read_run_missing_folder() -> None:
    """run= pointing nowhere says so."""
    with pytest.raises(SlipkitError, match="no such run folder"):
        read_run("/nonexistent/run")


def _toy(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(120, 2))
    y = (X[:, 0] + 0.3 * rng.normal(size=120) > 0).astype(int)
    groups = np.repeat(np.arange(6), 20)
    return X, y, groups


def test_optuna_search_is_deterministic_for_a_seed() -> None:
    """The same data and seed give the same best parameters and history."""
    from sklearn.linear_model import LogisticRegression

    X, y, g = _toy()
    kw: dict[str, Any] = {"space": {"C": [1e-3, 1e2, "log"]}, "n_trials": 5, "seed": 4}
    a = optuna_search(LogisticRegression(), X, y, g, **kw)
    b = optuna_search(LogisticRegression(), X, y, g, **kw)
    assert a == b
    assert 1e-3 <= a[0]["C"] <= 1e2


def test_optuna_search_needs_enough_groups() -> None:
    """Group CV with more folds than trials is refused before any fit."""
    from sklearn.linear_model import LogisticRegression

    X, y, _ = _toy()
    with pytest.raises(ValueError, match="needs >= 3 trials"):
        optuna_search(
            LogisticRegression(),
            X,
            y,
            np.zeros(len(y)),
            space={"C": [0.1, 1.0]},
            n_trials=1,
        )


def test_sweeper_runs_one_folder_per_job(tmp_path: Path) -> None:
    """`slipkit train -m` over a grid trains each job into its own run folder."""
    import subprocess
    import sys

    cmd = [
        sys.executable,
        "-c",
        "from slipkit.cli import main; main()",
        "train",
        "-m",
        "experiment=tactip_svm",
        "model.C=1,1000",
        "dataset.n_trials=4",
        f"runs_dir={tmp_path / 'runs'}",
        f"hydra.sweep.dir={tmp_path / 'multirun'}",
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert 0 == done.returncode, done.stderr[-2000:]
    runs = sorted((tmp_path / "runs" / "tactip_svm").iterdir())
    assert 2 == len(runs)
    assert all((r / "metrics.json").is_file() for r in runs)
    cs = {json.loads((r / "metrics.json").read_text())["params"]["C"] for r in runs}
    assert 2 == len(cs)


def test_sweep_selects_on_validation_and_prints_the_best_run(tmp_path: Path) -> None:
    """A sweep ranks runs by their validation objective; best.json and the printed lines
    name the best run and its value."""
    import subprocess
    import sys

    sweep = tmp_path / "multirun"
    cmd = [
        sys.executable,
        "-c",
        "from slipkit.cli import main; main()",
        "train",
        "-m",
        "experiment=tactip_svm",
        "model.C=0.01,1,1000",
        "dataset.n_trials=6",
        "scene.model.n_pins=19",
        "scene.model.duration_s=1.0",
        "scene.model.onset_s=[0.4,0.7]",
        "task.cv=2",
        f"runs_dir={tmp_path / 'runs'}",
        f"hydra.sweep.dir={sweep}",
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert 0 == done.returncode, done.stderr[-2000:]
    best = json.loads((sweep / "best.json").read_text())
    runs = {
        r: json.loads((r / "run.json").read_text())["objective"]
        for r in (tmp_path / "runs" / "tactip_svm").iterdir()
    }
    assert {"validation.balanced_accuracy"} == {o["name"] for o in runs.values()}
    assert max(o["value"] for o in runs.values()) == best["objective"]["value"]
    by_path = {str(r.resolve()): o["value"] for r, o in runs.items()}
    assert best["objective"]["value"] == by_path[best["run_dir"]]
    assert 3 == len(json.loads((sweep / "sweep.json").read_text())["jobs"])
    lines = done.stdout.splitlines()
    assert str(sweep / "best.json") == lines[-1]
    assert any(line.startswith("sweep best (by validation.") for line in lines)


def test_selection_record_lists_every_candidate_and_the_best() -> None:
    """The selection record holds each candidate's mean / std and the best of them."""
    from sklearn.linear_model import LogisticRegression

    from slipkit.train.search import format_best, selection_record

    X, y, g = _toy()
    space = {"C": [1e-3, 1e2, "log"], "fit_intercept": {"choices": [True, False]}}
    best, score, history = optuna_search(
        LogisticRegression(), X, y, g, space=space, n_trials=4, cv=3, seed=1
    )
    rec = selection_record(best, score, history, cv=3, scoring="balanced_accuracy")
    assert 4 == len(rec["candidates"])
    top = max(rec["candidates"], key=lambda c: c["mean"])
    assert (best, score) == (top["params"], top["mean"])
    assert {"C", "fit_intercept"} == set(rec["best"])
    assert "group-kfold by trial" in format_best(rec)


def test_group_cv_scores_each_fold_on_unseen_groups() -> None:
    """group_cv fits k clones, each scored on groups it never saw, and reports mean / std."""
    from sklearn.dummy import DummyClassifier

    from slipkit.train.search import group_cv

    X, y, g = _toy()
    val = group_cv(DummyClassifier(), X, y, g, cv=3, unit="object")
    assert ("group-kfold by object", 3, 3) == (val["cv"], val["k"], len(val["folds"]))
    assert [0.5, 0.5, 0.5] == val["folds"]  # a constant answer: balanced accuracy 0.5
