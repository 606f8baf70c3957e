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

A multirun over replicates (seeds, objects, folds: the ``replicates`` of the callback,
``seed`` and ``dataset.seed`` by default) is also folded into one table,
``aggregate.csv`` in the sweep folder (:func:`aggregate_sweep`): one row per estimator
and setting of the other swept parameters, with the number of runs and the mean, std
and Student-t confidence interval of the objective and of every numeric validation and
test metric (:func:`slipkit.evaluate.aggregate.aggregate`). The best run is still chosen
on the validation objective alone.

Any Hydra launcher runs the jobs: the basic one in sequence, ``hydra/launcher=joblib``
in parallel on one machine, ``hydra/launcher=submitit_slurm`` on a SLURM cluster
(docs/scale.md). Each job writes only its own run folder (atomically, named with its job
number) and its own job folder; the summary is written once, by the launching process.
"""

from __future__ import annotations

import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd
from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, ListConfig

from slipkit._files import first_line, read_json_object, write_out_file
from slipkit.errors import SlipkitError

log = logging.getLogger("slipkit.sweep")

JOB_FILE = "job.json"
AGGREGATE_FILE = "aggregate.csv"
#: Swept keys whose values are repetitions of one setting, not settings to compare.
REPLICATES = ("seed", "dataset.seed")
#: The metrics.json sections whose numeric leaves the aggregate table carries.
METRIC_SECTIONS = ("validation", "test")
#: Leaves that count things rather than score them (sample sizes, CV folds).
_BOOKKEEPING = frozenset({"n", "k", "debounce_k", "n_trials"})


def _has(*keys: str) -> Any:
    """A recogniser: a JSON object holding every one of ``keys``."""

    def test(path: Path) -> bool:
        obj = read_json_object(path)
        return obj is not None and set(keys) <= obj.keys()

    return test


#: file name -> (recogniser of what the multirun wrote there, what it is called): the
#: sweep folder may be a folder of the user's (``hydra.sweep.dir=...``), and a file of
#: the same name is replaced only when it is the multirun's own
OWN_FILES = {
    JOB_FILE: (_has("job", "run_dir", "overrides", "objective"), "a multirun job.json"),
    "sweep.json": (_has("objective", "jobs"), "a multirun sweep.json"),
    "best.json": (_has("job", "run_dir", "objective"), "a multirun best.json"),
    AGGREGATE_FILE: (
        lambda path: first_line(path).startswith("estimator,"),
        "a multirun aggregate.csv",
    ),
}


def _write(path: Path, text: str) -> None:
    """Write one of :data:`OWN_FILES` (never over a file the multirun did not write)."""
    is_own, what = OWN_FILES[path.name]
    write_out_file(path, text, option="hydra.sweep.dir", is_own=is_own, what=what)


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
    _write(path, json.dumps(payload, indent=2) + "\n")
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
    _write(
        sweep_dir / "sweep.json",
        json.dumps({"objective": best["objective"], "jobs": jobs}, indent=2) + "\n",
    )
    _write(sweep_dir / "best.json", json.dumps(best, indent=2) + "\n")
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


def _numeric_leaves(node: Any, prefix: str) -> dict[str, float]:
    """Every int / float leaf of a nested dict as ``{dotted.key: value}`` (None -> NaN)."""
    out: dict[str, float] = {}
    if isinstance(node, dict):
        for key, value in node.items():
            if key not in _BOOKKEEPING:
                out.update(_numeric_leaves(value, f"{prefix}.{key}"))
    elif node is None:
        out[prefix] = float("nan")
    elif isinstance(node, int | float) and not isinstance(node, bool):
        out[prefix] = float(node)
    return out


def _run_estimator(run_dir: Path) -> str:
    """The run's estimator class (``run.json`` 'model'), short name; '?' if unreadable."""
    try:
        run = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return "?"
    return str(run.get("model", "?")).rsplit(".", 1)[-1]


def aggregate_sweep(
    sweep_dir: Path, replicates: Sequence[str] = REPLICATES
) -> pd.DataFrame | None:
    """Fold a multirun's jobs into one table: per estimator and setting, mean / std / CI.

    Parameters
    ----------
    sweep_dir : Path
        The sweep folder holding ``<job>/job.json`` (written by :func:`record_job`).
    replicates : sequence of str
        Swept keys that repeat one setting (seeds, objects, folds); the other keys
        that vary between jobs define the groups, beside the estimator.

    Returns
    -------
    pandas.DataFrame or None
        One row per group: ``estimator``, the other swept keys, ``n`` (runs), then
        ``<metric>_mean`` / ``_std`` / ``_ci`` (95 % Student-t half-width, NaN for one
        run) for the objective (``objective``) and every numeric leaf of the runs'
        ``validation`` and ``test`` metrics but counts (``n``, ``k`` ...), in their
        units. Written to
        ``aggregate.csv`` atomically. None when no job recorded itself.
    """
    from slipkit.evaluate.aggregate import aggregate  # pandas / scipy: train extra

    jobs = [
        json.loads(p.read_text(encoding="utf-8"))
        for p in sorted(sweep_dir.glob(f"*/{JOB_FILE}"))
    ]
    if not jobs:
        return None
    jobs.sort(key=lambda j: int(j["job"]))
    values: dict[str, set[str]] = {}
    for job in jobs:
        for item in job["overrides"]:
            key, _, value = item.partition("=")
            values.setdefault(key.lstrip("+~"), set()).add(value)
    swept = [k for k, v in values.items() if len(v) > 1]
    groups = [k for k in swept if k not in set(replicates)]
    rows = []
    for job in jobs:
        run = Path(job["run_dir"])
        params = _sweep_params(job["overrides"], set(groups))
        row: dict[str, Any] = {"estimator": _run_estimator(run)}
        row.update({k: params.get(k, "") for k in groups})
        row["objective"] = float(job["objective"]["value"])
        try:
            metrics = json.loads((run / "metrics.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            metrics = {}
        for section in METRIC_SECTIONS:
            row.update(_numeric_leaves(metrics.get(section), section))
        rows.append(row)
    by = ["estimator", *groups]
    df = pd.DataFrame(rows)
    metric_cols = [c for c in df.columns if c not in by]
    df[metric_cols] = df[metric_cols].apply(pd.to_numeric, errors="coerce")
    table = aggregate(df, by=by, metrics=metric_cols)
    _write(sweep_dir / AGGREGATE_FILE, table.to_csv(index=False))
    return table


def aggregate_lines(table: pd.DataFrame, objective: str) -> list[str]:
    """The aggregate table as printed: per group, n and the objective and test scores
    as ``mean ± CI`` (the whole table is in ``aggregate.csv``)."""
    group_cols = list(table.columns[: list(table.columns).index("n")])
    shown = ["objective"] + [
        c[: -len("_mean")]
        for c in table.columns
        if c.startswith("test.") and c.endswith("_mean")
    ]
    shown = [m for m in shown if table[f"{m}_mean"].notna().any()][:6]
    lines = [
        f"aggregate over replicates (mean ± 95 % CI; objective = {objective}):",
    ]
    for _, row in table.iterrows():
        head = ", ".join(f"{c}={row[c]}" for c in group_cols)
        cells = []
        for m in shown:
            mean, ci = row[f"{m}_mean"], row[f"{m}_ci"]
            ci_txt = "" if pd.isna(ci) else f" ± {ci:.3g}"
            cells.append(f"{m} {mean:.4g}{ci_txt}")
        lines.append(f"  {head} (n={int(row['n'])}): " + "; ".join(cells))
    return lines


class SweepSummary(Callback):
    """Hydra callback: at the end of a multirun, print and save the best run and the
    aggregate table.

    Parameters
    ----------
    replicates : sequence of str
        Swept keys whose values repeat one setting (see :func:`aggregate_sweep`);
        set with ``hydra.callbacks.sweep_summary.replicates=[seed,task.test_object]``.
    """

    def __init__(self, replicates: Sequence[str] | None = None) -> None:
        if isinstance(replicates, ListConfig):
            replicates = [str(r) for r in replicates]
        self.replicates = tuple(REPLICATES if replicates is None else replicates)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(str(config.hydra.sweep.dir))
        if not sweep_dir.is_dir():
            return
        try:
            self._summarise(sweep_dir)
        except SlipkitError as exc:
            # Hydra turns a callback's exception into a warning: say it in one line.
            print(f"slipkit: error: {exc}; sweep summary not written", file=sys.stderr)

    def _summarise(self, sweep_dir: Path) -> None:
        best = summarise_sweep(sweep_dir)
        if best is None:
            return
        n_jobs = len(list(sweep_dir.glob(f"*/{JOB_FILE}")))
        for line in best_lines(best, n_jobs):
            print(line)
        table = aggregate_sweep(sweep_dir, self.replicates)
        if table is not None:
            for line in aggregate_lines(table, best["objective"]["name"]):
                print(line)
            print(sweep_dir / AGGREGATE_FILE)
        print(sweep_dir / "best.json")


__all__ = [
    "AGGREGATE_FILE",
    "JOB_FILE",
    "OWN_FILES",
    "REPLICATES",
    "SweepSummary",
    "aggregate_lines",
    "aggregate_sweep",
    "best_lines",
    "record_job",
    "summarise_sweep",
]
