"""Run folders: what ``slipkit train`` writes and ``slipkit evaluate`` reads.

A run folder holds::

    config.yaml     the resolved config that made the run (re-run it with --config-dir)
    run.json        slipkit version, experiment, task, dataset fingerprint and provenance,
                    the objective, and the sha256 of every other file the run wrote
                    (``files``; the model's also as ``model_sha256``)
    metrics.json    the task's metrics (train / val / test sides, tables' numbers)
    model.joblib    the fitted estimator (scikit-learn's documented persistence)
    train.log       the log of the run
    *.csv *.md *.png  the task's tables and plots
    evaluations/<name>/metrics.json  one folder per ``slipkit evaluate`` dataset

``model.joblib`` is a pickle: a run folder is a training-machine artefact, loaded
only after its sha256 matches ``run.json``. :func:`read_run` checks every file listed in
``files`` the same way, so ``slipkit evaluate`` and ``slipkit export`` never use (or
sign into a bundle) a config or a metric edited after training. What ships to a gripper
PC is an ONNX bundle (``slipkit export``), never this file.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from slipkit._files import (
    atomic_write_text,
    final_path,
    recover_leftovers,
    sha256_bytes,
    sha256_file,
)
from slipkit.errors import SlipkitError

RUN_FORMAT = "slipkit-run"
#: 2: ``files``, the sha256 of every file of the run (1: the model's only)
RUN_SCHEMA_VERSION = 2
MODEL_FILE = "model.joblib"
#: files of a run folder not checksummed: run.json holds the sums, the log is only read
#: by people (it is still written to after run.json)
UNCHECKED_FILES = frozenset({"run.json", "train.log"})


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
    """The resolved config as ``config.yaml`` (Hydra's own node left out).

    ``run_dir``, when set, is recorded as the folder the run will have, not a
    temporary one it is written in (a run inside ``slipkit compare``'s output).
    """
    container = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(container, dict)
    container.pop("hydra", None)
    if container.get("run_dir"):
        container["run_dir"] = str(final_path(str(container["run_dir"])))
    atomic_write_text(folder / "config.yaml", OmegaConf.to_yaml(container))


def file_checksums(folder: Path) -> dict[str, str]:
    """sha256 of every file under ``folder`` but :data:`UNCHECKED_FILES`, by relative
    path (``/``-separated, sorted): the ``files`` field of ``run.json``."""
    out = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = path.relative_to(folder).as_posix()
        if rel not in UNCHECKED_FILES:
            out[rel] = sha256_file(path)
    return out


@dataclass(frozen=True)
class Run:
    """A run folder as read back: its config, its run.json, its fitted model and its
    metrics (``metrics.json``, parsed from the bytes whose sha256 was checked)."""

    path: Path
    config: DictConfig
    info: dict[str, Any]
    model: Any
    metrics: dict[str, Any] = field(default_factory=dict)


def _checked_bytes(folder: Path, rel: str, want: Any) -> bytes:
    """The bytes of ``folder/rel``, refused unless their sha256 is ``want``."""
    path = folder / rel
    if not path.is_file():
        raise SlipkitError(
            f"{path}: listed in run.json field 'files' but missing; the run folder "
            "was changed after training"
        )
    data = path.read_bytes()
    digest = sha256_bytes(data)
    if digest != want:
        raise SlipkitError(
            f"{path}: sha256 {digest[:12]}... does not match run.json field 'files'; "
            "the file was changed after training"
        )
    return data


def _dotted(metrics: Any, name: str) -> Any:
    for key in name.split("."):
        if not isinstance(metrics, dict) or key not in metrics:
            return None
        metrics = metrics[key]
    return metrics


def _check_objective(info_path: Path, info: dict[str, Any], metrics: Any) -> None:
    """run.json's objective value must be the one metrics.json holds (both finite)."""
    objective = info.get("objective")
    if not isinstance(objective, dict) or not isinstance(objective.get("name"), str):
        return
    recorded, scored = objective.get("value"), _dotted(metrics, objective["name"])
    if not (isinstance(recorded, int | float) and isinstance(scored, int | float)):
        return
    if not (math.isfinite(recorded) and math.isfinite(scored)):
        return
    if not math.isclose(recorded, scored, rel_tol=1e-9, abs_tol=1e-12):
        raise SlipkitError(
            f"{info_path}: field 'objective.value' is {recorded} but metrics.json "
            f"holds {objective['name']} = {scored}; run.json was changed after training"
        )


def read_run(path: Path | str) -> Run:
    """Load a run folder, checking its format and the sha256 of every file ``run.json``
    lists (``files``), and that its objective is the one ``metrics.json`` holds.

    Raises
    ------
    SlipkitError
        Naming the folder and the missing or inconsistent file; a run written before
        ``files`` was recorded is refused (re-train it).
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
    files = info.get("files")
    if not isinstance(files, dict):
        raise SlipkitError(
            f"{info_path}: no field 'files' (written by "
            f"{info.get('written_by', 'an older slipkit')}): its config and metrics "
            "cannot be checked against what training wrote; re-train the run"
        )
    for rel in ("config.yaml", "metrics.json", MODEL_FILE):
        if rel not in files:
            raise SlipkitError(f"{info_path}: field 'files' does not list {rel}")
    for rel, want in files.items():
        # only names inside the folder: run.json is data, not a path to follow
        if Path(rel).is_absolute() or ".." in Path(rel).parts:
            raise SlipkitError(
                f"{info_path}: field 'files' names {rel!r}, not a file inside the run"
            )
        if rel == MODEL_FILE:
            if want != digest:  # checked above as model_sha256
                raise SlipkitError(
                    f"{info_path}: fields 'files' and 'model_sha256' disagree on "
                    f"{MODEL_FILE}"
                )
        elif rel not in ("config.yaml", "metrics.json"):  # read (and checked) below
            _checked_bytes(folder, rel, want)
    config = OmegaConf.create(
        _checked_bytes(folder, "config.yaml", files["config.yaml"]).decode("utf-8")
    )
    assert isinstance(config, DictConfig)
    try:
        metrics = json.loads(
            _checked_bytes(folder, "metrics.json", files["metrics.json"])
        )
    except json.JSONDecodeError as exc:
        raise SlipkitError(
            f"{folder / 'metrics.json'}: not valid JSON ({exc})"
        ) from exc
    _check_objective(info_path, info, metrics)
    return Run(folder, config, info, joblib.load(folder / MODEL_FILE), metrics)
