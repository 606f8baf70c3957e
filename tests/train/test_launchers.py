"""Multiruns through Hydra launchers (joblib in parallel, submitit's local executor) and
the aggregate table a multirun over replicates writes."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from slipkit.train.sweep import AGGREGATE_FILE, JOB_FILE, aggregate_sweep

# A TacTip SVM grid small enough to train in about a second per job.
_TINY = [
    "experiment=tactip_svm",
    "dataset.n_trials=4",
    "scene.model.n_pins=19",
    "scene.model.duration_s=1.0",
    "scene.model.onset_s=[0.4,0.7]",
    "task.cv=2",
]


def _multirun(tmp_path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    cmd = [
        sys.executable,
        "-c",
        "from slipkit.cli import main; main()",
        "train",
        "-m",
        *_TINY,
        f"runs_dir={tmp_path / 'runs'}",
        f"hydra.sweep.dir={tmp_path / 'multirun'}",
        *extra,
    ]
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


def _fake_job(
    sweep: Path, job: int, overrides: list[str], objective: float, test: dict
) -> None:
    run = sweep.parent / "runs" / f"r{job}"
    run.mkdir(parents=True)
    (run / "run.json").write_text(json.dumps({"model": "pkg.models.FakeSVM"}))
    (run / "metrics.json").write_text(
        json.dumps({"validation": {"score": objective, "k": 3}, "test": test})
    )
    (sweep / str(job)).mkdir(parents=True)
    payload = {
        "job": job,
        "run_dir": str(run),
        "overrides": overrides,
        "objective": {
            "name": "validation.score",
            "direction": "maximize",
            "value": objective,
        },
    }
    (sweep / str(job) / JOB_FILE).write_text(json.dumps(payload))


def test_aggregate_sweep_folds_seeds_into_one_row_per_setting(tmp_path: Path) -> None:
    """Jobs differing only in seed share a row: n, mean, sample std and t-interval."""
    sweep = tmp_path / "multirun"
    grid = [("1", "0", 0.6, 0.5), ("1", "1", 0.8, 0.7), ("10", "0", 0.9, None)]
    for job, (c, seed, val, acc) in enumerate(grid):
        _fake_job(
            sweep, job, ["e=x", f"model.C={c}", f"seed={seed}"], val, {"acc": acc}
        )
    table = aggregate_sweep(sweep)
    assert table is not None
    assert ["estimator", "model.C", "n"] == list(table.columns[:3])
    assert [("FakeSVM", "1", 2), ("FakeSVM", "10", 1)] == [
        tuple(r) for r in table[["estimator", "model.C", "n"]].itertuples(index=False)
    ]
    first = table.iloc[0]
    assert pytest.approx(0.7) == first["objective_mean"]
    assert pytest.approx(math.sqrt(0.02)) == first["objective_std"]
    # t_{0.975, 1} = 12.706...; half-width = t * std / sqrt(2)
    assert pytest.approx(12.7062047 * 0.1, rel=1e-6) == first["objective_ci"]
    assert "validation.k_mean" not in table.columns  # a count, not a score
    assert math.isnan(
        table.iloc[1]["test.acc_mean"]
    )  # a metric the run did not measure
    on_disk = pd.read_csv(sweep / AGGREGATE_FILE, dtype={"model.C": str})
    assert list(table.columns) == list(on_disk.columns)
    assert table["n"].tolist() == on_disk["n"].tolist()


def test_aggregate_sweep_groups_by_the_replicates_given(tmp_path: Path) -> None:
    """Keys named as replicates fold; a seed not named stays a group column."""
    sweep = tmp_path / "multirun"
    for job, (obj, seed) in enumerate([("a", "0"), ("a", "1"), ("b", "0")]):
        _fake_job(sweep, job, [f"task.object={obj}", f"seed={seed}"], 0.5, {})
    table = aggregate_sweep(sweep, replicates=["task.object"])
    assert table is not None
    assert [("0", 2), ("1", 1)] == [
        tuple(r) for r in table[["seed", "n"]].itertuples(index=False)
    ]


def test_aggregate_sweep_without_jobs_writes_nothing(tmp_path: Path) -> None:
    """A sweep folder with no job.json gives no table and no file."""
    assert aggregate_sweep(tmp_path) is None
    assert not (tmp_path / AGGREGATE_FILE).exists()


@pytest.mark.slow
def test_joblib_launcher_runs_concurrent_jobs_into_their_own_folders(
    tmp_path: Path,
) -> None:
    """Four jobs, two at a time (joblib): four complete run folders, no leftovers, one
    job.json each naming its own run, and the seeds folded in aggregate.csv."""
    done = _multirun(
        tmp_path,
        "model.C=1,1000",
        "seed=0,1",
        "hydra/launcher=joblib",
        "hydra.launcher.n_jobs=2",
    )
    assert 0 == done.returncode, done.stderr[-2000:]
    runs = sorted((tmp_path / "runs" / "tactip_svm").iterdir())
    assert 4 == len(runs)
    assert [] == [r.name for r in runs if r.name.startswith(".")]  # no temp leftover
    assert all((r / "run.json").is_file() for r in runs)
    jobs = [
        json.loads(p.read_text())
        for p in sorted((tmp_path / "multirun").glob(f"*/{JOB_FILE}"))
    ]
    assert [0, 1, 2, 3] == sorted(j["job"] for j in jobs)
    assert {str(r.resolve()) for r in runs} == {j["run_dir"] for j in jobs}
    for j in jobs:
        cfg = (Path(j["run_dir"]) / "config.yaml").read_text()
        c = next(o for o in j["overrides"] if o.startswith("model.C="))
        assert f"C: {c.split('=')[1]}" in cfg  # each run holds its own job's config
    table = pd.read_csv(tmp_path / "multirun" / AGGREGATE_FILE)
    assert [1, 1000] == table["model.C"].tolist()
    assert [2, 2] == table["n"].tolist()
    lines = done.stdout.splitlines()
    assert str(tmp_path / "multirun" / "best.json") == lines[-1]
    assert str(tmp_path / "multirun" / AGGREGATE_FILE) in lines


@pytest.mark.slow
def test_submitit_local_launcher_runs_the_grid(tmp_path: Path) -> None:
    """The SLURM launcher's code path through submitit's local executor: each job
    trains into its own run folder and the sweep summary sees both."""
    done = _multirun(
        tmp_path,
        "model.C=1,1000",
        "hydra/launcher=submitit_local",
        "hydra.launcher.timeout_min=10",
    )
    assert 0 == done.returncode, done.stderr[-2000:]
    runs = sorted((tmp_path / "runs" / "tactip_svm").iterdir())
    assert 2 == len(runs)
    sweep = json.loads((tmp_path / "multirun" / "sweep.json").read_text())
    assert {str(r.resolve()) for r in runs} == {j["run_dir"] for j in sweep["jobs"]}
    assert (tmp_path / "multirun" / AGGREGATE_FILE).is_file()
