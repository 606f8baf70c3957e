"""``slipkit train`` and ``slipkit evaluate``.

``train`` composes ``configs/train.yaml`` (an ``experiment=`` picks scene or
source, model and task), builds every object with ``hydra.utils.instantiate``,
lets the task split, fit and score, and writes the run folder atomically. It returns
the task's objective, which ``slipkit sweep`` (:mod:`slipkit.train.optuna_sweep`)
optimises across runs.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import logging
import math
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
    file_checksums,
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
            check_params(model, "detector" if cfg.get("detector") else "model")
            dataset = training_dataset(cfg)
            log.info("dataset: %r", dataset)
            check_trainable(dataset, task)
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
                    # every file a later command reads (config, metrics, tables, model)
                    "files": file_checksums(tmp),
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
    """One warning line when the evaluated dataset overlaps the training data (none
    when the task scored only trials its fit never trains on: ``held_out_only``)."""
    if info.get("held_out_only"):
        return ""
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
        # what `slipkit evaluate` checks a new dataset against (sensor layout)
        "streams": {
            name: {"channels": list(spec.channels), "rate_hz": spec.rate_hz}
            for name, spec in sorted(dataset.streams.items())
        },
    }


def check_params(model: Any, what: str) -> None:
    """Check an estimator's hyper-parameters against its ``_parameter_constraints``
    before any data is built or fitted (scikit-learn checks them only in ``fit``).

    Raises
    ------
    SlipkitError
        ``<what>: The 'C' parameter of TacTipSVM must be ...`` (scikit-learn's message).
    """
    if not hasattr(model, "_parameter_constraints"):
        return
    from sklearn.utils._param_validation import InvalidParameterError

    try:
        model._validate_params()
    except InvalidParameterError as exc:
        raise SlipkitError(f"{what}: {exc}") from None


#: task options naming the stream(s) an estimator reads (their channels must match)
INPUT_STREAM_KEYS = ("stream", "pdc_stream")
#: task options naming further streams the task scores against (they must be present)
TRUTH_STREAM_KEYS = ("truth_stream", "target")


def check_trainable(dataset: Any, task: Task) -> None:
    """Refuse, in one line, a dataset the task cannot learn from.

    Parameters
    ----------
    dataset : Dataset
        The training dataset (a folder, a raw recording or a simulation).
    task : Task
        The run's task; its ``stream`` / ``pdc_stream`` / ``channels`` name what the
        estimator reads.

    Raises
    ------
    SlipkitError
        The dataset holds no trials, lacks a stream the task reads, a channel the
        estimator reads holds no finite value (all NaN or infinite), or the class
        label the task learns (``task.label``) has fewer than two classes in it.
    """
    import numpy as np

    if len(dataset) == 0:
        raise SlipkitError(
            f"dataset {dataset.name!r} holds no trials; there is nothing to train on"
        )
    label = getattr(task, "label", None)
    labels = getattr(dataset, "labels", None) or {}
    spec = labels.get(label) if isinstance(label, str) else None
    if spec is not None and spec.classes is not None and label in dataset.trials:
        seen = sorted(map(str, dataset.trials[label].dropna().unique()))
        if len(seen) < 2:
            raise SlipkitError(
                f"task.label={label}: dataset {dataset.name!r} has "
                f"{'one class ' + repr(seen[0]) if seen else 'no class'} in its "
                f"{len(dataset)} trials; a classifier needs trials of at least two classes"
            )
    for key in INPUT_STREAM_KEYS:
        name = getattr(task, key, None)
        if not isinstance(name, str):
            continue
        if name not in dataset.streams:
            raise SlipkitError(
                f"task.{key}={name}: dataset {dataset.name!r} (sensor "
                f"{dataset.sensor!r}) holds no stream {name!r}; streams: "
                f"{sorted(dataset.streams)}"
            )
        table = dataset.tables[name]
        wanted = getattr(task, "channels", None) if key == "stream" else None
        channels = (
            [str(c) for c in wanted]
            if isinstance(wanted, list | tuple)
            else list(dataset.streams[name].channels)
        )
        if not len(table):
            continue  # an event stream may hold no rows; the task judges that
        for channel in channels:
            if channel not in table.columns:
                raise SlipkitError(
                    f"task.channels: stream {name!r} of dataset {dataset.name!r} has "
                    f"no channel {channel!r}; channels: "
                    f"{list(dataset.streams[name].channels)}"
                )
            values = np.asarray(table[channel], dtype=np.float64)
            if not np.isfinite(values).any():
                raise SlipkitError(
                    f"dataset {dataset.name!r}: stream {name!r} channel {channel!r} "
                    f"has no finite value in its {len(values)} rows (all NaN or "
                    "infinite); there is nothing to train on"
                )


def _preview(channels: list[str]) -> str:
    shown = ", ".join(channels[:4])
    return f"[{shown}{', ...' if len(channels) > 4 else ''}]"


def check_fits_run(run: Any, dataset: Any, where: Path) -> None:
    """Refuse, in one line, a dataset whose sensor or stream layout differs from the run's.

    A fitted estimator reads the channels it was trained on: a TacTip with another
    pin count, or another sensor, would reach the model as the wrong number of
    features, and a stream at another sample rate as windows of another length.
    Compared with ``run.json`` (``dataset.sensor`` and ``dataset.streams``): the
    sensor, the presence of every stream the run's task names, and the sample rate
    and channels of the stream(s) it reads.

    Raises
    ------
    SlipkitError
        Naming the dataset folder, the run, and both values that differ.
    """
    trained = dict(run.info.get("dataset") or {})
    what = (
        f"dataset {where} ({dataset.name!r}, sensor {dataset.sensor!r}) does not fit "
        f"run {run.path}"
    )
    origin = f"trained on {trained.get('name', '?')!r}"
    sensor = trained.get("sensor")
    if sensor is not None and str(sensor) != str(dataset.sensor):
        raise SlipkitError(
            f"{what}: the run was {origin} from sensor {sensor!r}, this dataset is from "
            f"sensor {dataset.sensor!r}"
        )
    streams = dict(trained.get("streams") or {})
    task_cfg = run.config.get("task") or {}
    for key in (*INPUT_STREAM_KEYS, *TRUTH_STREAM_KEYS):
        name = task_cfg.get(key)
        if not isinstance(name, str):
            continue
        if key in TRUTH_STREAM_KEYS and name not in streams:
            continue  # not recorded as a training stream (or an older run.json)
        if name not in dataset.streams:
            raise SlipkitError(
                f"{what}: the run's task reads stream {name!r} (task.{key}), which "
                f"this dataset does not hold; streams: {sorted(dataset.streams)}"
            )
        if key not in INPUT_STREAM_KEYS or name not in streams:
            continue
        trained_hz, have_hz = (
            streams[name].get("rate_hz"),
            dataset.streams[name].rate_hz,
        )
        if (
            trained_hz is not None
            and have_hz is not None
            # relative tolerance: a rate computed from timestamps carries float noise
            and not math.isclose(float(trained_hz), float(have_hz), rel_tol=1e-6)
        ):
            raise SlipkitError(
                f"{what}: stream {name!r} is sampled at {float(have_hz):g} Hz, the run "
                f"was {origin} at {float(trained_hz):g} Hz"
            )
        want = [str(c) for c in streams[name].get("channels") or []]
        have = list(dataset.streams[name].channels)
        chosen = task_cfg.get("channels") if key == "stream" else None
        if chosen is not None:
            missing = [str(c) for c in chosen if str(c) not in have]
            if missing:
                raise SlipkitError(
                    f"{what}: the run reads channels {missing} of stream {name!r} "
                    f"(task.channels), which this dataset lacks; its channels: "
                    f"{_preview(have)}"
                )
        elif (
            want
            and want != have
            # pooled TacTip models read any pin count (slipkit.families.tactip.detector)
            and not getattr(run.model, "pin_count_independent", False)
        ):
            raise SlipkitError(
                f"{what}: stream {name!r} has {len(have)} channels {_preview(have)}, "
                f"the run was {origin} with {len(want)} {_preview(want)}"
            )


def evaluate_main(cfg: DictConfig) -> Path:
    """Score the run ``cfg.run`` on the dataset folder ``cfg.dataset``.

    Writes ``<run>/evaluations/<name>/metrics.json`` (name: ``cfg.name`` or the dataset
    folder's name and fingerprint) and prints its path last. The dataset folder is only
    read.
    """
    run = read_run(Path(str(cfg.run)))
    dataset = load_dataset(Path(str(cfg.dataset)))
    check_fits_run(run, dataset, Path(str(cfg.dataset)))
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
                "held_out_only": bool(metrics.get("held_out_only", False)),
            },
            **jsonable(metrics),
        }
        write_json(tmp / "metrics.json", payload)
    for line in task.headline(metrics):  # a detector's operating point first
        print(line)
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


__all__ = [
    "check_fits_run",
    "check_params",
    "check_trainable",
    "evaluate_main",
    "seed_everything",
    "train_main",
]
