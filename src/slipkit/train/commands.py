"""``slipkit train`` and ``slipkit evaluate``.

``train`` composes ``configs/train.yaml`` (an ``experiment=`` picks scene or
source, model and task), builds every object with ``hydra.utils.instantiate``,
lets the task split, fit and score, and writes the run folder atomically. It returns
the task's objective so the Hydra Optuna sweeper (``-m hydra/sweeper=optuna``) can
optimise across runs.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import logging
import random
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from hydra.core.hydra_config import HydraConfig
from hydra.errors import InstantiationException
from hydra.utils import instantiate
from omegaconf import DictConfig

import slipkit
from slipkit._files import atomic_dir, check_out_path, child_folder
from slipkit.data.io import load_dataset
from slipkit.errors import SlipkitError
from slipkit.train.data import training_dataset
from slipkit.train.runs import (
    RUN_FORMAT,
    RUN_SCHEMA_VERSION,
    new_run_dir,
    read_run,
    save_model,
    write_config,
    write_json,
)
from slipkit.train.sweep import record_job
from slipkit.train.task import Task, jsonable

log = logging.getLogger("slipkit.train")


def seed_everything(seed: int) -> None:
    """Seed Python, numpy's legacy global state and torch (when a model loaded it)."""
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - libraries that still read the global state
    if "torch" in sys.modules:
        import torch

        torch.manual_seed(seed)


def build(node: DictConfig, what: str) -> Any:
    """``instantiate(node)``, logging its target; a SlipkitError inside is unwrapped."""
    log.info("%s: %s", what, node.get("_target_"))
    try:
        return instantiate(node)
    except InstantiationException as exc:
        if isinstance(exc.__cause__, SlipkitError):
            raise exc.__cause__ from None
        raise


def estimator_node(cfg: DictConfig) -> DictConfig:
    """The estimator a run fits: ``cfg.detector`` (an analytic detector) if chosen, else ``cfg.model``."""
    node = cfg.get("detector")
    return node if node is not None else cfg.model


def _job_num() -> int | None:
    if not HydraConfig.initialized():
        return None
    hc = HydraConfig.get()
    return int(hc.job.num) if str(hc.mode) == "RunMode.MULTIRUN" else None


def _log_to(path: Path) -> logging.Handler:
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(
        logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s")
    )
    logging.getLogger("slipkit").addHandler(handler)
    logging.getLogger("slipkit").setLevel(logging.INFO)
    return handler


def train_main(cfg: DictConfig) -> float:
    """Train ``cfg.model`` with ``cfg.task`` on ``cfg.dataset``; print the run folder last."""
    seed = int(cfg.seed)
    seed_everything(seed)
    target = (
        Path(str(cfg.run_dir))
        if cfg.get("run_dir")
        else new_run_dir(Path(str(cfg.runs_dir)), str(cfg.name), job=_job_num())
    )
    overwrite = bool(cfg.get("overwrite", False))
    check_out_path(
        target,
        inputs={
            "dataset.path": cfg.dataset.get("path"),
            "dataset.raw": cfg.dataset.get("raw"),
        },
        option="run_dir" if cfg.get("run_dir") else "runs_dir",
        kind="run",
        overwrite=overwrite,
    )
    with atomic_dir(target, overwrite=overwrite, kind="run") as tmp:
        handler = _log_to(tmp / "train.log")
        try:
            start = time.perf_counter()
            task: Task = build(cfg.task, "task")
            model = build(estimator_node(cfg), "model")
            dataset = training_dataset(cfg)
            log.info("dataset: %r", dataset)
            seed_everything(seed)  # model constructors may have imported torch
            result = task.fit(model, dataset, seed=seed, out=tmp)
            objective = task.objective_value(result.metrics)
            elapsed = time.perf_counter() - start
            model_sha = save_model(result.model, tmp)
            write_config(cfg, tmp)
            write_json(tmp / "metrics.json", jsonable(result.metrics))
            write_json(
                tmp / "run.json",
                {
                    "format": RUN_FORMAT,
                    "schema_version": RUN_SCHEMA_VERSION,
                    "name": str(cfg.name),
                    "written_by": f"slipkit {slipkit.__version__}",
                    "created_utc": dt.datetime.now(dt.UTC).isoformat(
                        timespec="seconds"
                    ),
                    "seed": seed,
                    "task": str(cfg.task._target_),
                    "model": str(estimator_node(cfg)._target_),
                    "model_file": "model.joblib",
                    "model_sha256": model_sha,
                    "objective": {
                        "name": task.objective,
                        "direction": task.direction,
                        "value": objective,
                    },
                    "dataset": _dataset_info(dataset, cfg),
                    "train_seconds": round(elapsed, 3),
                },
            )
            log.info("%s = %.6g (%s)", task.objective, objective, task.direction)
        finally:
            logging.getLogger("slipkit").removeHandler(handler)
            handler.close()
    for line in result.summary:
        print(line)
    # In a multirun, tell the sweep summary (slipkit.train.sweep) where this run is.
    record_job(
        target,
        {"name": task.objective, "direction": task.direction, "value": objective},
    )
    print(target)
    return objective


def _provenance_digest(dataset: Any) -> str:
    """sha256 of the dataset's provenance (JSON, sorted keys)."""
    import hashlib
    import json

    text = json.dumps(dataset.provenance, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _shared_trials(info: dict[str, Any], dataset: Any) -> int | None:
    """Trials of ``dataset`` whose id was in the run's training dataset, when both
    datasets have the same provenance (0 when it differs); None for runs written
    before run.json recorded trial ids."""
    trained = info.get("dataset", {})
    if "trial_ids" not in trained:
        return None
    if trained.get("provenance_sha256") != _provenance_digest(dataset):
        return 0
    return len(set(map(str, dataset.trial_ids)) & set(trained["trial_ids"]))


def _overlap_line(info: dict[str, Any]) -> str:
    """One warning line when the evaluated dataset overlaps the training data."""
    if info["seen_in_training"]:
        return (
            "warning: this is the training dataset (same fingerprint): the scores "
            "include the trials the model was fitted on, not held-out data"
        )
    shared = info.get("trials_in_training_dataset")
    if shared:
        return (
            f"warning: {shared} of {info['n_trials']} trials have the ids and "
            "provenance of trials in the training dataset: the scores are not "
            "held-out data"
        )
    return ""


def _dataset_info(dataset: Any, cfg: DictConfig) -> dict[str, Any]:
    node = cfg.dataset
    origin = (
        {"path": str(node.path)}
        if node.get("path")
        else {"raw": str(node.raw), "source": str(cfg.source._target_)}
        if node.get("raw")
        else {
            "scene": str(cfg.scene.name),
            "n_trials": int(node.n_trials),
            "seed": int(node.seed),
        }
    )
    return {
        "name": dataset.name,
        "sensor": dataset.sensor,
        "n_trials": len(dataset),
        "fingerprint": dataset.fingerprint(),
        **origin,
        # what `slipkit evaluate` checks trial overlap against (same ids + provenance)
        "provenance_sha256": _provenance_digest(dataset),
        "trial_ids": [str(t) for t in dataset.trial_ids],
    }


def evaluate_main(cfg: DictConfig) -> Path:
    """Score the run ``cfg.run`` on the dataset folder ``cfg.dataset``.

    Writes ``<run>/evaluations/<name>/metrics.json`` (name: ``cfg.name`` or the dataset
    folder's name and fingerprint) and prints its path last. The dataset folder is only
    read.
    """
    run = read_run(Path(str(cfg.run)))
    dataset = load_dataset(Path(str(cfg.dataset)))
    task: Task = build(run.config.task, "task")
    seed_everything(int(run.config.get("seed", 0)))
    fingerprint = dataset.fingerprint()
    name = (
        str(cfg.name)
        if cfg.get("name") is not None
        else f"{Path(str(cfg.dataset)).resolve().name.lstrip('.')}-{fingerprint[:8]}"
    )
    # A plain name under <run>/evaluations/ only; an existing folder there is replaced
    # only when it is an evaluation (re-evaluating under the same name).
    target = child_folder(run.path / "evaluations", name, option="name")
    check_out_path(
        target,
        inputs={"dataset": cfg.dataset},
        option="name",
        kind="evaluation",
        overwrite=True,
        inside=run.path,
    )
    with atomic_dir(target, overwrite=True, kind="evaluation", inside=run.path) as tmp:
        metrics = task.evaluate(run.model, dataset, out=tmp)
        payload = {
            "run": str(run.path),
            "dataset": {
                "path": str(cfg.dataset),
                "name": dataset.name,
                "sensor": dataset.sensor,
                "n_trials": len(dataset),
                "fingerprint": fingerprint,
                "seen_in_training": fingerprint
                == run.info.get("dataset", {}).get("fingerprint"),
                "trials_in_training_dataset": _shared_trials(run.info, dataset),
            },
            **jsonable(metrics),
        }
        write_json(tmp / "metrics.json", payload)
    overlap = _overlap_line(payload["dataset"])
    if overlap:
        print(overlap)
    # The run's objective is a validation score; evaluate scores the same metric on
    # the dataset as a whole (``test.<metric>``).
    scored = task.objective.replace("validation.", "test.", 1)
    with contextlib.suppress(KeyError):  # a task may not score its objective here
        value = task.objective_value(metrics, scored)
        print(f"{scored} = {value:.4g}")
    out = target / "metrics.json"
    print(out)
    return out


__all__ = ["evaluate_main", "seed_everything", "train_main"]
