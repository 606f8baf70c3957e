"""Run folders: what ``slipkit train`` writes and ``slipkit evaluate`` reads.

A run folder holds::

    config.yaml     the resolved config that made the run (re-run it with --config-dir)
    run.json        slipkit version, experiment, task, dataset fingerprint and provenance,
                    the model file's sha256, the objective
    metrics.json    the task's metrics (train / val / test sides, tables' numbers)
    model.joblib    the fitted estimator (scikit-learn's documented persistence)
    train.log       the log of the run
    *.csv *.md *.png  the task's tables and plots
    evaluations/<name>/metrics.json  one folder per ``slipkit evaluate`` dataset

``model.joblib`` is a pickle: a run folder is a training-machine artefact, loaded
only after its sha256 matches ``run.json``. What ships to a gripper PC is an ONNX
bundle (``slipkit export``), never this file.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from slipkit._files import atomic_write_text, recover_leftovers, sha256_file
from slipkit.errors import SlipkitError

RUN_FORMAT = "slipkit-run"
RUN_SCHEMA_VERSION = 1
MODEL_FILE = "model.joblib"


def new_run_dir(runs_dir: Path, name: str, *, job: int | None = None) -> Path:
    """A not-yet-existing folder ``runs_dir/name/<UTC timestamp>[_<job>][-k]``."""
    stamp = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d_%H-%M-%S")
    base = runs_dir / name / (stamp if job is None else f"{stamp}_{job}")
    candidate, k = base, 1
    while candidate.exists() or _tmp_siblings(candidate):
        candidate = base.with_name(f"{base.name}-{k}")
        k += 1
    return candidate


def _tmp_siblings(path: Path) -> bool:
    return path.parent.exists() and any(path.parent.glob(f".{path.name}.tmp-*"))


def write_json(path: Path, payload: dict[str, Any]) -> None:
    """``payload`` as indented JSON, written atomically."""
    atomic_write_text(path, json.dumps(payload, indent=2, sort_keys=False) + "\n")


def save_model(model: Any, folder: Path) -> str:
    """Dump ``model`` to ``folder/model.joblib``; return its sha256."""
    import joblib

    path = folder / MODEL_FILE
    joblib.dump(model, path)
    return sha256_file(path)


def write_config(cfg: DictConfig, folder: Path) -> None:
    """The resolved config as ``config.yaml`` (Hydra's own node left out)."""
    container = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(container, dict)
    container.pop("hydra", None)
    atomic_write_text(folder / "config.yaml", OmegaConf.to_yaml(container))


@dataclass(frozen=True)
class Run:
    """A run folder as read back: its config, its run.json and its fitted model."""

    path: Path
    config: DictConfig
    info: dict[str, Any]
    model: Any


def read_run(path: Path | str) -> Run:
    """Load a run folder, checking its format and the model file's sha256.

    Raises
    ------
    SlipkitError
        Naming the folder and the missing or inconsistent file.
    """
    import joblib

    folder = Path(path)
    recover_leftovers(folder)  # an interrupted overwrite: restore or report it
    if not folder.is_dir():
        raise SlipkitError(f"{folder}: no such run folder (run=...)")
    info_path = folder / "run.json"
    for needed in (info_path, folder / "config.yaml", folder / MODEL_FILE):
        if not needed.is_file():
            raise SlipkitError(
                f"{folder}: not a slipkit run folder ({needed.name} is missing)"
            )
    try:
        info = json.loads(info_path.read_text())
    except json.JSONDecodeError as exc:
        raise SlipkitError(f"{info_path}: not valid JSON ({exc})") from exc
    if info.get("format") != RUN_FORMAT:
        raise SlipkitError(f"{info_path}: field 'format' is not {RUN_FORMAT!r}")
    if int(info.get("schema_version", 0)) > RUN_SCHEMA_VERSION:
        raise SlipkitError(
            f"{info_path}: schema_version {info['schema_version']} is newer than this "
            f"slipkit reads ({RUN_SCHEMA_VERSION}); upgrade slipkit"
        )
    digest = sha256_file(folder / MODEL_FILE)
    if digest != info.get("model_sha256"):
        raise SlipkitError(
            f"{folder / MODEL_FILE}: sha256 {digest[:12]}... does not match run.json "
            "field 'model_sha256'; the model file was changed after training"
        )
    config = OmegaConf.load(folder / "config.yaml")
    assert isinstance(config, DictConfig)
    return Run(folder, config, info, joblib.load(folder / MODEL_FILE))
