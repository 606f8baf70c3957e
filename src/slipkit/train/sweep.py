"""What a ``slipkit train -m`` sweep chose: the best run by its validation objective.

A multirun here is a grid (``slipkit train -m experiment=tactip_svm model.C=1,10,100``,
Hydra's basic sweeper, run by any Hydra launcher). A search that proposes the next
parameters from the previous results is ``slipkit sweep``
(:mod:`slipkit.train.optuna_sweep`), an Optuna study with the same rule: ranked by the
validation objective.

Each job of a multirun writes ``job.json`` into its Hydra job folder
(``<sweep dir>/<job number>/``): its run folder, its overrides and the run's objective
(:func:`record_job`, called by ``slipkit train``). When the sweep ends, the Hydra
callback :class:`SweepSummary` (``hydra.callbacks`` in ``configs/train.yaml``) reads
them, prints the best run and its parameters, and writes ``sweep.json`` (every job,
best first) and ``best.json`` into the sweep folder. The objective is the task's
validation score (group CV on the training side), so the choice never looks at the
test data; the test scores of the best run are printed beside it for reading only.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from slipkit._files import atomic_write_text

log = logging.getLogger("slipkit.sweep")

JOB_FILE = "job.json"


def record_job(run_dir: Path, objective: dict[str, Any]) -> Path | None:
    """Write ``job.json`` (run folder, overrides, objective) into the Hydra job folder.

    Does nothing outside a multirun. Returns the file written, if any.
    """
    if not HydraConfig.initialized():
        return None
    hc = HydraConfig.get()
    if str(hc.mode) != "RunMode.MULTIRUN":
        return None
    folder = Path(str(hc.runtime.output_dir))
    folder.mkdir(parents=True, exist_ok=True)
    payload = {
        "job": int(hc.job.num),
        "run_dir": str(Path(run_dir).resolve()),
        "overrides": list(hc.overrides.task),
        "objective": objective,
    }
    path = folder / JOB_FILE
    atomic_write_text(path, json.dumps(payload, indent=2) + "\n")
    return path


def _sweep_params(overrides: list[str], swept: set[str]) -> dict[str, str]:
    params = {}
    for item in overrides:
        key, _, value = item.partition("=")
        if key.lstrip("+~") in swept:
            params[key.lstrip("+~")] = value
    return params


def summarise_sweep(sweep_dir: Path) -> dict[str, Any] | None:
    """Read every ``job.json`` under ``sweep_dir``; write ``sweep.json`` and
    ``best.json``; return the best job (None when no job recorded itself)."""
    jobs = []
    for path in sorted(sweep_dir.glob(f"*/{JOB_FILE}")):
        job = json.loads(path.read_text(encoding="utf-8"))
        run = Path(job["run_dir"])
        metrics_file = run / "metrics.json"
        if metrics_file.is_file():
            metrics = json.loads(metrics_file.read_text(encoding="utf-8"))
            for key in ("params", "selection"):
                if key in metrics:
                    job[key] = metrics[key]
            test = metrics.get("test")
            if isinstance(test, dict):
                job["test_for_reading_only"] = {
                    k: v for k, v in test.items() if isinstance(v, int | float)
                }
        jobs.append(job)
    if not jobs:
        return None
    direction = jobs[0]["objective"]["direction"]
    sign = -1.0 if direction == "maximize" else 1.0
    jobs.sort(key=lambda j: sign * float(j["objective"]["value"]))
    # What the sweep varied: overrides whose value differs between jobs.
    values: dict[str, set[str]] = {}
    for job in jobs:
        for item in job["overrides"]:
            key, _, value = item.partition("=")
            values.setdefault(key.lstrip("+~"), set()).add(value)
    swept = {k for k, v in values.items() if len(v) > 1}
    for job in jobs:
        job["swept"] = _sweep_params(job["overrides"], swept)
    best = jobs[0]
    atomic_write_text(
        sweep_dir / "sweep.json",
        json.dumps({"objective": best["objective"], "jobs": jobs}, indent=2) + "\n",
    )
    atomic_write_text(sweep_dir / "best.json", json.dumps(best, indent=2) + "\n")
    return best


def best_lines(best: dict[str, Any], n_jobs: int | None = None) -> list[str]:
    """The lines printed at the end of a sweep."""
    obj = best["objective"]
    swept = ", ".join(f"{k}={v}" for k, v in best["swept"].items()) or "(none varied)"
    lines = [
        f"sweep best (by {obj['name']}, {obj['direction']}, validation on the training "
        f"side): {obj['value']:.6g} -- job {best['job']}"
        + (f" of {n_jobs}" if n_jobs else ""),
        f"  swept parameters: {swept}",
    ]
    if "params" in best:
        lines.append(f"  model parameters: {json.dumps(best['params'])}")
    lines.append(f"  run: {best['run_dir']}")
    return lines


class SweepSummary(Callback):
    """Hydra callback: at the end of a multirun, print and save the best run."""

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(str(config.hydra.sweep.dir))
        if not sweep_dir.is_dir():
            return
        best = summarise_sweep(sweep_dir)
        if best is None:
            return
        n_jobs = len(list(sweep_dir.glob(f"*/{JOB_FILE}")))
        for line in best_lines(best, n_jobs):
            print(line)
        print(sweep_dir / "best.json")


__all__ = ["JOB_FILE", "SweepSummary", "best_lines", "record_job", "summarise_sweep"]
