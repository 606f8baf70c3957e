"""TacTip tasks end to end: experiment=tactip_svm and experiment=tactip_table1 (paper Table I)."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path
from typing import Any

import joblib
import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given
from hypothesis import strategies as st
from omegaconf import DictConfig

import slipkit
from slipkit.data.dataset import Dataset
from slipkit.data.io import save_dataset
from slipkit.errors import SlipkitError
from slipkit.families.tactip import task as tactip_module
from slipkit.families.tactip.task_table import (
    LINEAR_DEFAULT_C,
    PAPER_TABLE1,
    TacTipTable1,
    _majority,
)
from slipkit.models.svm import TacTipSVM
from slipkit.sim.commands import build_scene
from slipkit.train import search as search_module
from slipkit.train.commands import evaluate_main, train_main
from slipkit.train.runs import read_run

#: Short trials of 19 pins (the centre and two rings) keep every run around a second.
SMALL_SCENE = [
    "scene.model.n_pins=19",
    "scene.model.duration_s=1.0",
    "scene.model.onset_s=[0.4,0.7]",
]
#: Table I on 12 runs of three objects (seed 0: 4 flat, so 2 train / 2 test flat runs),
#: with a 2-candidate search and 2-fold group CV per row.
SMALL_TABLE = [
    "experiment=tactip_table1",
    *SMALL_SCENE,
    "scene.model.objects=[flat,r20,r80]",
    "dataset.n_trials=12",
    "task.search.n_trials=2",
    "task.search.cv=2",
]
SMALL_SVM = [
    "experiment=tactip_svm",
    *SMALL_SCENE,
    "dataset.n_trials=8",
    "task.search.n_trials=2",
    "task.search.cv=2",
]
RUN_FILES = {"config.yaml", "run.json", "metrics.json", "model.joblib", "train.log"}
TABLE_FILES = {"table1.csv", "table1.md", "curved.csv", "curved.md", "table1.png"}
PAPER_PERCENT = [99.11, 98.95, 97.21, 95.07, 94.66, 70.58, 99.88]


def _compose(config: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        return compose(config_name=config, overrides=overrides)


def train(overrides: list[str], run: Path) -> Path:
    """Run ``slipkit train`` in-process into the folder ``run``."""
    train_main(_compose("train", [*overrides, f"run_dir={run}"]))
    return run


def metrics_of(run: Path) -> dict[str, Any]:
    return json.loads((run / "metrics.json").read_text())


def folder_state(path: Path) -> dict[str, tuple[str, int]]:
    """sha256 and mtime (ns) of every file under ``path``."""
    return {
        str(p.relative_to(path)): (
            hashlib.sha256(p.read_bytes()).hexdigest(),
            p.stat().st_mtime_ns,
        )
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def table_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train(SMALL_TABLE, tmp_path_factory.mktemp("table") / "run")


@pytest.fixture(scope="module")
def svm_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train(SMALL_SVM, tmp_path_factory.mktemp("svm") / "run")


@pytest.fixture(scope="module")
def small_dataset() -> Dataset:
    """The in-memory dataset of SMALL_TABLE (12 runs: flat, r20, r80)."""
    cfg = _compose("train", SMALL_TABLE)
    return build_scene(cfg.scene).simulate(12, 0, progress=False)


@pytest.fixture
def search_spy(monkeypatch: pytest.MonkeyPatch) -> list[set[str]]:
    """Trial ids of the frames handed to every in-run Optuna search."""
    seen: list[set[str]] = []

    def spy(*args: Any, **kwargs: Any) -> Any:
        seen.append(set(map(str, args[3])))  # (estimator, X, y, groups)
        return search_module.optuna_search(*args, **kwargs)

    monkeypatch.setattr(tactip_module, "optuna_search", spy)
    return seen


# -- experiment=tactip_svm ------------------------------------------------------
def test_tactip_svm_run_writes_every_file(svm_run: Path) -> None:
    """experiment=tactip_svm writes the run files, the test predictions and the per-trial
    events at the chosen debounce."""
    assert RUN_FILES | {"test_predictions.csv", "test_events.csv"} == {
        p.name for p in svm_run.iterdir()
    }
    info = json.loads((svm_run / "run.json").read_text())
    assert "validation.balanced_accuracy" == info["objective"]["name"]
    m = metrics_of(svm_run)
    assert m["validation"]["balanced_accuracy"] == info["objective"]["value"]
    assert m["selection"]["best_score"] == info["objective"]["value"]


def test_tactip_svm_records_the_selection(svm_run: Path) -> None:
    """The in-run search writes its method, CV, best parameters and every candidate."""
    sel = metrics_of(svm_run)["selection"]
    assert ("optuna-tpe", "group-kfold by trial", "balanced_accuracy") == (
        sel["method"],
        sel["cv"],
        sel["scoring"],
    )
    assert 2 == len(sel["candidates"])
    assert {"C", "gamma"} == set(sel["best"])
    best = max(sel["candidates"], key=lambda c: c["mean"])
    assert (best["params"], best["mean"]) == (sel["best"], sel["best_score"])


def _corrupt_test_side(dataset: Dataset, test_ids: list[str]) -> Dataset:
    """``dataset`` with the slip onsets of ``test_ids`` moved to 0.1 s (wrong labels)."""
    trials = dataset.trials.copy()
    trials.loc[trials["trial_id"].isin(test_ids), "slip_onset_s"] = 0.1
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


@pytest.mark.parametrize("search", [True, False])
def test_test_labels_cannot_change_the_selection_or_the_objective(
    tmp_path: Path, search: bool
) -> None:
    """Corrupting the test side's labels leaves the chosen model and the objective as they were."""
    from slipkit.data.splits import split_by_trial

    cfg = _compose("train", SMALL_SVM)
    dataset = build_scene(cfg.scene).simulate(8, 0, progress=False)
    search_cfg = {
        "n_trials": 2,
        "cv": 2,
        "space": {"C": [1.0, 1e4, "log"], "gamma": [1e-5, 1e-1, "log"]},
    }
    task = tactip_module.TacTipFrames(search=search_cfg if search else None, cv=2)
    test_ids = list(split_by_trial(dataset, test_size=0.5, seed=0).test)
    corrupted = _corrupt_test_side(dataset, test_ids)
    runs = []
    for i, ds in enumerate((dataset, corrupted)):
        (tmp_path / str(i)).mkdir()
        result = task.fit(
            TacTipSVM(C=686.6, gamma=6.6e-4), ds, seed=0, out=tmp_path / str(i)
        )
        runs.append(result)
    clean, bad = (r.metrics for r in runs)
    assert clean["test"]["accuracy"] != bad["test"]["accuracy"]  # the test side changed
    assert clean.get("selection") == bad.get("selection")
    assert clean["validation"] == bad["validation"]
    assert clean["params"] == bad["params"]
    assert task.objective_value(clean) == task.objective_value(bad)


def test_tactip_svm_search_sees_only_the_training_half(
    tmp_path: Path, search_spy: list[set[str]]
) -> None:
    """The in-run search of experiment=tactip_svm gets frames of training trials only."""
    run = train(SMALL_SVM, tmp_path / "run")
    split = metrics_of(run)["split"]
    assert 1 == len(search_spy)
    assert set(split["train"]) == search_spy[0]
    assert set() == search_spy[0] & set(split["test"])


# -- experiment=tactip_table1 ---------------------------------------------------
def test_table1_run_writes_every_file(table_run: Path) -> None:
    """experiment=tactip_table1 writes the run files, both tables (csv + md) and the plot."""
    assert RUN_FILES | TABLE_FILES == {p.name for p in table_run.iterdir()}
    assert (table_run / "table1.png").stat().st_size > 10_000


def test_table1_has_seven_rows_with_the_published_figures(table_run: Path) -> None:
    """Six kernel x feature rows ('all slip frames') and the N=4 row, beside the paper's %."""
    table = pd.read_csv(table_run / "table1.csv")
    rows = metrics_of(table_run)["rows"]
    assert PAPER_PERCENT == table["paper_percent"].tolist()
    assert PAPER_PERCENT == [r["paper_percent"] for r in rows]
    assert ["all"] * 6 + ["4"] == table["slip_frames"].astype(str).tolist()
    assert ["Gaussian"] * 3 + ["linear"] * 3 + ["Gaussian"] == table["kernel"].tolist()
    for r in rows:
        p = r["params"]
        if r["kernel"] == "rbf":
            assert pytest.approx(1.0 / np.sqrt(p["gamma"])) == p["kernel_scale"]
        assert "optuna" == r["params_source"]
        assert {"balanced_accuracy", "detection"} <= set(r["test"])
    md = (table_run / "table1.md").read_text()
    assert "99.88" in md
    assert "balanced" in md


def test_table1_saves_the_main_row_and_scores_its_objective(table_run: Path) -> None:
    """model.joblib is the N=4 Gaussian (dr, dtheta) SVM; the objective is its validation score."""
    metrics = metrics_of(table_run)
    main = next(r for r in metrics["rows"] if r["main"])
    model = joblib.load(table_run / "model.joblib")
    assert ("gaussian_dr_dtheta_n4", 4) == (main["name"], main["n_slip"])
    assert (2 * 19, "rbf") == (model.n_features_in_, model.kernel)
    assert pytest.approx(main["params"]["C"]) == model.C
    assert main["test"] == metrics["test"]
    info = json.loads((table_run / "run.json").read_text())
    assert "validation.balanced_accuracy" == info["objective"]["name"]
    assert main["selection"]["best_score"] == info["objective"]["value"]
    assert main["selection"] == metrics["selection"]


def test_table1_curved_rows_name_the_objects(table_run: Path) -> None:
    """Curved rows: the held-out flat runs, then every other object of the dataset."""
    curved = metrics_of(table_run)["curved"]
    assert ["flat", "r20", "r80"] == sorted(c["object"] for c in curved)
    assert "held-out runs" == curved[0]["role"]
    assert {"novel (not in training)"} == {c["role"] for c in curved[1:]}
    table = pd.read_csv(table_run / "curved.csv")
    assert [c["object"] for c in curved] == table["object"].tolist()
    assert 12 == sum(c["n_trials"] for c in curved) + len(
        metrics_of(table_run)["split"]["train"]
    )


def test_table1_same_config_twice_gives_identical_metrics(
    table_run: Path, tmp_path: Path
) -> None:
    """Re-running the same config (in-run searches included) gives the same metrics.json."""
    again = train(SMALL_TABLE, tmp_path / "again")
    assert metrics_of(table_run) == metrics_of(again)


def test_table1_searches_see_only_training_trials(
    tmp_path: Path, search_spy: list[set[str]]
) -> None:
    """Each row's search gets frames of the flat training half only, never a test run."""
    run = train(SMALL_TABLE, tmp_path / "run")
    metrics = metrics_of(run)
    held_out = set(metrics["split"]["test"])
    assert len(PAPER_TABLE1) == len(search_spy)
    for seen in search_spy:
        assert set(metrics["split"]["train"]) == seen
        assert set() == seen & held_out


def test_table1_without_search_uses_the_paper_parameters(tmp_path: Path) -> None:
    """Search off: Gaussian rows get the paper's KS / BC, linear rows fitcsvm's C = 1."""
    run = train([*SMALL_TABLE, "task.search.n_trials=0"], tmp_path / "run")
    for r, paper in zip(metrics_of(run)["rows"], PAPER_TABLE1, strict=True):
        if r["kernel"] == "rbf":
            assert "paper" == r["params_source"]
            assert pytest.approx(paper.paper_ks) == r["params"]["kernel_scale"]
            assert pytest.approx(paper.paper_bc) == r["params"]["C"]
        else:
            assert ("fitcsvm default", LINEAR_DEFAULT_C) == (
                r["params_source"],
                r["params"]["C"],
            )
    val = metrics_of(run)["validation"]  # 2 flat training runs: 2 folds, not 3
    assert ("group-kfold by trial", 2) == (val["cv"], val["k"])
    assert 2 == len(val["folds"])


# -- evaluate and run folders ----------------------------------------------------
def test_evaluate_scores_a_fresh_dataset_without_touching_it(
    table_run: Path, tmp_path: Path
) -> None:
    """evaluate writes <run>/evaluations/<name>/metrics.json and leaves the dataset as it was."""
    cfg = _compose("train", SMALL_TABLE)
    fresh = build_scene(cfg.scene).simulate(4, 7, progress=False)
    folder = save_dataset(fresh, tmp_path / "fresh")
    before = folder_state(folder)
    out = evaluate_main(
        _compose("evaluate", [f"run={table_run}", f"dataset={folder}", "name=fresh"])
    )
    assert table_run / "evaluations" / "fresh" / "metrics.json" == out
    payload = json.loads(out.read_text())
    assert (4, False) == (
        payload["dataset"]["n_trials"],
        payload["dataset"]["seen_in_training"],
    )
    assert 4 == sum(o["n_trials"] for o in payload["per_object"])
    assert 0.0 <= payload["test"]["accuracy"] <= 1.0
    assert before == folder_state(folder)


def test_altered_model_file_is_refused(table_run: Path, tmp_path: Path) -> None:
    """A run whose model.joblib changed after training is refused, naming the file."""
    copy = Path(shutil.copytree(table_run, tmp_path / "run"))
    with (copy / "model.joblib").open("ab") as fh:
        fh.write(b"\0")
    with pytest.raises(SlipkitError, match=r"model\.joblib.*changed after training"):
        read_run(copy)


def test_bad_run_path_is_a_clear_error(tmp_path: Path) -> None:
    """evaluate run=<missing folder> raises SlipkitError naming the folder."""
    with pytest.raises(SlipkitError, match="no such run folder"):
        evaluate_main(
            _compose("evaluate", [f"run={tmp_path / 'nope'}", f"dataset={tmp_path}"])
        )


# -- the task's own checks ---------------------------------------------------------
def test_too_few_trials_of_the_table_object_is_refused(small_dataset: Dataset) -> None:
    """Table I on an object with no runs names the object and the counts per object."""
    task = TacTipTable1(objects=["r40"])
    with pytest.raises(SlipkitError, match=r"objects=\['r40'\].*dataset\.n_trials"):
        task.partition(small_dataset)


def test_missing_curved_object_or_group_is_refused(small_dataset: Dataset) -> None:
    """An absent curved object, or a dataset without the group column, is named."""
    with pytest.raises(SlipkitError, match=r"curved_objects.*r40"):
        TacTipTable1(curved_objects=["r40"]).partition(small_dataset)
    with pytest.raises(SlipkitError, match="no trial group 'shape'"):
        TacTipTable1(group="shape").partition(small_dataset)


def test_linear_rows_search_C_only_and_are_standardised() -> None:
    """A linear row drops gamma from the search space and fits on z-scored features."""
    space = {"C": [0.1, 10.0, "log"], "gamma": [1e-3, 1.0, "log"]}
    task = TacTipTable1(search={"n_trials": 2, "space": space})
    linear = next(r for r in PAPER_TABLE1 if r.kernel == "linear")
    gaussian = PAPER_TABLE1[0]
    assert {"C": space["C"]} == task.row_task(linear).search["space"]  # type: ignore[index]
    assert space == task.row_task(gaussian).search["space"]  # type: ignore[index]
    est, source = task.row_estimator(TacTipSVM(), linear)
    assert ("linear", True, "optuna") == (est.kernel, est.standardize, source)
    est, _ = task.row_estimator(TacTipSVM(), gaussian)
    assert False is est.standardize


def test_non_svm_model_is_refused() -> None:
    """The table needs an estimator with a kernel parameter; others get a clear error."""
    from sklearn.linear_model import LogisticRegression

    with pytest.raises(SlipkitError, match="model=tactip_svm"):
        TacTipTable1().row_estimator(LogisticRegression(), PAPER_TABLE1[0])


@given(st.lists(st.sampled_from(["slip", "static"]), min_size=1, max_size=50))
def test_majority_baseline_is_the_best_constant_answer(labels: list[str]) -> None:
    """The majority baseline equals the accuracy of the better constant prediction."""
    y = np.asarray(labels)
    expected = max(np.mean(y == "slip"), np.mean(y == "static"))
    assert pytest.approx(expected) == _majority(y)


def test_tactip_svm_same_config_twice_gives_identical_metrics(
    svm_run: Path, tmp_path: Path
) -> None:
    """experiment=tactip_svm with its in-run search gives the same metrics.json twice."""
    assert metrics_of(svm_run) == metrics_of(train(SMALL_SVM, tmp_path / "again"))


def test_evaluate_on_the_training_data_says_so_in_one_line(
    svm_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Evaluating on the training dataset, or some of its trials, prints one warning line."""
    from slipkit.train.data import training_dataset

    same = training_dataset(_compose("train", SMALL_SVM))
    for name, ds, seen, shared in (
        ("same", same, True, 8),
        ("part", same.subset(same.trial_ids[:3]), False, 3),
    ):
        folder = save_dataset(ds, tmp_path / name)
        capsys.readouterr()
        out = evaluate_main(
            _compose(
                "evaluate", [f"run={svm_run}", f"dataset={folder}", f"name={name}"]
            )
        )
        lines = capsys.readouterr().out.splitlines()
        info = json.loads(out.read_text())["dataset"]
        assert (seen, shared) == (
            info["seen_in_training"],
            info["trials_in_training_dataset"],
        )
        assert 1 == sum(line.startswith("warning:") for line in lines)
        assert str(out) == lines[-1]
        assert any(line.startswith("test.balanced_accuracy = ") for line in lines)
