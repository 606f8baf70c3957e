"""``slipkit compare comparison=<family>``: learned against analytic, accuracy against its cost.

Composes ``configs/compare.yaml``; the ``comparison`` group
(``configs/comparison/<family>.yaml``) names the data (a scene, or a source and a raw
recording), the task, and the estimators (learned models from ``configs/model``,
analytic detectors from ``configs/detector``). Each estimator runs through
``slipkit train``'s own code path (:func:`slipkit.train.commands.train_main`) with the
same task and the same seed, so every task splits identically (checked: the split
each run records must be equal); its run folder is kept under ``<out>/runs/``. A
per-task adapter (:mod:`slipkit.compare.adapters`) reduces each run's metrics to one
unified row; :mod:`slipkit.compare.costs` adds the fit time and the compute per
frame of the exported bundle through the runtime loop. The output folder
(``runs/compare/<name>/<UTC time>`` or ``out=``, written atomically) holds
``report.md``, ``metrics.csv`` and the PNGs; the report's path is printed last.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from hydra.utils import get_class
from omegaconf import DictConfig, OmegaConf

import slipkit.families as _families
from slipkit._files import atomic_dir, check_out_path
from slipkit._options import SEEDS, check_value
from slipkit.compare import plots
from slipkit.compare.adapters import Evaluation, RunView, adapt
from slipkit.compare.costs import DeployCost, FitTimer, deploy_cost, quiet_console
from slipkit.compare.report import write_report
from slipkit.compare.table import (
    VERDICT_KEYS,
    block_p99,
    build_table,
    quiet_p99,
    seed_table,
    verdict_cost,
    verdict_limits,
)
from slipkit.errors import SlipkitError
from slipkit.progress import quiet_progress
from slipkit.train.runs import new_run_dir

log = logging.getLogger("slipkit.compare")


@dataclass
class Comparison:
    """A finished comparison.

    Attributes
    ----------
    folder : Path
        The output folder (report.md, metrics.csv, PNGs, runs/).
    report : Path
        ``folder / "report.md"``.
    table : DataFrame
        The unified table (``metrics.csv``).
    evaluations : dict
        Estimator name -> :class:`~slipkit.compare.adapters.Evaluation`.
    costs : dict
        Estimator name -> :class:`~slipkit.compare.costs.DeployCost` (with several
        seeds: every seed's decisions pooled, p99 as :func:`~slipkit.compare.table.block_p99`).
    seeds : list of int
        The seeds the comparison ran (one: the table is that run's; several: means).
    runs : dict
        Estimator name -> its run folder relative to ``folder`` (the first seed's:
        the one a deployment exports).
    per_seed : DataFrame or None
        With several seeds, one row per (estimator, seed) (``seeds.csv``).
    """

    folder: Path
    report: Path
    table: pd.DataFrame
    evaluations: dict[str, Evaluation] = field(default_factory=dict)
    costs: dict[str, DeployCost] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=list)
    runs: dict[str, Path] = field(default_factory=dict)
    per_seed: pd.DataFrame | None = None

    def run_dir(self, estimator: str) -> Path:
        """The run folder of ``estimator`` (the first seed's) under :attr:`folder`."""
        return self.folder / self.runs.get(estimator, Path("runs") / estimator)


def _is_analytic(name: str, node: dict[str, Any], analytic: list[str]) -> bool:
    """Whether the estimator trains as a detector (``detector:`` slot of the train config)."""
    module = str(node.get("_target_", "")).rpartition(".")[0]
    return name in analytic or _families.detector_module(module)


def _kind(node: dict[str, Any], analytic: bool) -> str:
    """The row's kind: a class's own ``slipkit_kind`` tag (a detector that fits a model, such
    as a logistic regression on onset features, says ``"learned"``), else by its slot."""
    try:
        tag = getattr(get_class(str(node.get("_target_", ""))), "slipkit_kind", None)
    except Exception:  # the class was checked before training; no tag then
        tag = None
    if tag in ("analytic", "learned"):
        return str(tag)
    return "analytic" if analytic else "learned"


def _train_config(
    comp: dict[str, Any],
    est: str,
    node: dict[str, Any],
    *,
    analytic: bool,
    seed: int,
    data_root: str,
    run_dir: Path,
) -> DictConfig:
    """The ``slipkit train`` config of one estimator of the comparison."""
    task = dict(comp["task"])
    override = dict((comp.get("task_overrides") or {}).get(est) or {})
    if override.get("_target_") and override["_target_"] != task.get("_target_"):
        # A whole task of another class (e.g. the stream-detection task of an analytic
        # TacTip detector beside the frame task of the SVMs): it replaces the family's
        # task; the checked split (by trial, same seed and test_size) stays shared.
        task = override
    else:
        task.update(override)
    verdict = comp.get("verdict")
    if isinstance(task.get("operating_point"), Mapping) and isinstance(
        verdict, Mapping
    ):
        # one declaration: the verdict's cost and limits choose each operating point
        task["operating_point"] = {
            **task["operating_point"],
            **{k: v for k, v in verdict.items() if k in VERDICT_KEYS},
        }
    cfg = OmegaConf.create(
        {
            "name": f"{comp['name']}-{est}",
            "seed": seed,
            "runs_dir": "runs",
            "run_dir": str(run_dir),
            "overwrite": False,
            "data_root": data_root,
            "scene": comp.get("scene"),
            "source": comp.get("source"),
            "model": None if analytic else node,
            "detector": node if analytic else None,
            "task": task,
            "dataset": comp["dataset"],
        }
    )
    return cfg


def _container(node: Any) -> dict[str, Any]:
    """A resolved plain-dict copy of a config node."""
    out = OmegaConf.to_container(node, resolve=True)
    if not isinstance(out, dict):
        raise SlipkitError(
            f"expected a mapping in the config, got {type(out).__name__}"
        )
    return {str(k): v for k, v in out.items()}


def _command(cfg: DictConfig) -> str:
    from hydra.core.hydra_config import HydraConfig

    if HydraConfig.initialized():
        overrides = list(HydraConfig.get().overrides.task)
        return " ".join(["slipkit compare", *overrides])
    given = cfg.get("command")
    if given:
        return str(given)
    return "slipkit compare " + " ".join(sys.argv[1:])


def _run_one(
    comp: dict[str, Any],
    est: str,
    node: dict[str, Any],
    cfg: DictConfig,
    runs: Path,
    bundles: Path,
    cost_cfg: dict[str, Any],
    analytic: list[str],
    seed: int,
) -> tuple[dict[str, Any], Evaluation, DeployCost, str]:
    """Train (or calibrate) one estimator through the task, adapt its metrics, export and time it."""
    from slipkit.train.commands import build, train_main
    from slipkit.train.data import training_dataset
    from slipkit.train.runs import read_run

    kind_analytic = _is_analytic(est, node, analytic)
    tcfg = _train_config(
        comp,
        est,
        node,
        analytic=kind_analytic,
        seed=seed,
        data_root=str(cfg.get("data_root", "")),
        run_dir=runs / est,
    )
    timer = FitTimer()
    buf = io.StringIO()
    t0 = time.perf_counter()
    with (
        timer.patch(get_class(str(node["_target_"]))),
        contextlib.redirect_stdout(buf),
        quiet_console(),
        quiet_progress(),
    ):
        train_main(tcfg)
    task_s = time.perf_counter() - t0
    summary = "\n".join(buf.getvalue().splitlines()[:-1])  # last line: the folder
    run = read_run(runs / est)
    task = build(run.config.task, "task")
    view = RunView(
        task=task,
        metrics=json.loads((runs / est / "metrics.json").read_text()),
        folder=runs / est,
        model=run.model,
        dataset=training_dataset(run.config),
    )
    ev = adapt(view)
    if bool(cost_cfg.get("export", True)):
        cost = deploy_cost(
            runs / est,
            bundles / est,
            max_frames=int(cost_cfg.get("max_frames", 2000)),
            warmup=int(cost_cfg.get("warmup", 50)),
            keep=bool(cost_cfg.get("keep_bundles", False)),
        )
        if cost.exported:
            # the p99 the budget is checked on: median of block p99s (one stall of a
            # shared machine does not flip the verdict; slipkit.compare.table.block_p99)
            cost.p99_us = block_p99(cost.latency_us)
    else:
        cost = DeployCost(False, "not measured (cost.export=false)")
    row = {
        "estimator": est,
        "kind": _kind(node, kind_analytic),
        "class": str(node["_target_"]).rsplit(".", 1)[-1],
        **ev.row,
        "fit_s": timer.total_s,
        "fit_calls": len(timer.calls),
        "task_s": task_s,
        "p50_us": cost.p50_us,
        "p99_us": cost.p99_us,
        "budget_p99_us": cost.budget_p99_us,
        "frame_period_us": cost.frame_period_us,
        "within_budget": cost.within_budget,
        "export": cost.note,
        "p99_quiet_us": quiet_p99(cost.latency_us) if cost.exported else math.nan,
        "p99_unpaced_us": cost.p99_unpaced_us,
    }
    return row, ev, cost, summary


def _task_needs(task: Any) -> tuple[tuple[type, ...], tuple[type, ...], str] | None:
    """What ``task`` can fit, as the task declares it (:meth:`Task.estimator_rule`):
    (accepted estimator classes, refused classes, what it feeds); None: no class check."""
    rule = getattr(task, "estimator_rule", None)
    return rule() if callable(rule) else None


def check_estimators(comp: dict[str, Any], cfg: DictConfig) -> None:
    """Refuse, before any training, an estimator the family's task or data cannot feed.

    For every estimator of the comparison (with its ``task_overrides``): its class
    must be one the task fits (a stream task runs an analytic detector; a frame or
    window task fits a learned classifier or regressor), its constructor must accept
    its config, and on the family's data (built once here, as each run builds it) the
    task's stream must exist with the channels the task names, a ``rate_hz`` the
    estimator declares must be the stream's, and an ``n_channels`` the stream's
    channel count.

    Raises
    ------
    SlipkitError
        Naming the comparison, the estimator and why it cannot run.
    """
    from slipkit.train.commands import build, check_params
    from slipkit.train.data import training_dataset

    name = comp.get("name")
    estimators: dict[str, dict[str, Any]] = dict(comp.get("estimators") or {})
    analytic = [str(a) for a in comp.get("analytic") or []]
    plans: list[tuple[str, dict[str, Any], Any]] = []
    tcfg: DictConfig | None = None
    for est, node in estimators.items():
        where = f"comparison {name!r}: estimator {est!r}"
        if not isinstance(node, dict) or not node.get("_target_"):
            raise SlipkitError(
                f"{where}: no _target_ (a configs/model or configs/detector entry)"
            )
        try:
            cls = get_class(str(node["_target_"]))
        except Exception as exc:  # hydra raises ImportError / ValueError variants
            raise SlipkitError(
                f"{where}: _target_ {node['_target_']!r} is not an importable class ({exc})"
            ) from None
        tcfg = _train_config(
            comp,
            est,
            node,
            analytic=_is_analytic(est, node, analytic),
            seed=int(cfg.seed),
            data_root=str(cfg.get("data_root", "")),
            run_dir=Path("unused"),
        )
        task = build(tcfg.task, "task")
        needs = _task_needs(task)
        if needs is not None:
            accepted, refused, feeds = needs
            if not issubclass(cls, accepted) or issubclass(cls, refused):
                raise SlipkitError(
                    f"{where} ({cls.__name__}) cannot run in this family's task: "
                    f"{type(task).__name__} {feeds}"
                )
        # A constructor or parameter refusing its config fails here, not after
        # other estimators have trained.
        check_params(
            build(OmegaConf.create(node), "model"),
            f"comparison.estimators.{est}",
        )
        plans.append((est, node, task))
    if tcfg is None:
        return
    dataset = training_dataset(tcfg)  # the same data every estimator's run builds
    for est, node, task in plans:
        where = f"comparison {name!r}: estimator {est!r}"
        stream = getattr(task, "stream", None)
        if not isinstance(stream, str):
            continue
        if stream not in dataset.streams:
            raise SlipkitError(
                f"{where}: its task reads stream {stream!r}, which the family's data "
                f"({dataset.name!r}, sensor {dataset.sensor!r}) does not hold; streams: "
                f"{sorted(dataset.streams)}"
            )
        spec = dataset.streams[stream]
        chosen = getattr(task, "channels", None)
        channels = list(spec.channels)
        if isinstance(chosen, list | tuple):
            missing = [str(c) for c in chosen if str(c) not in channels]
            if missing:
                raise SlipkitError(
                    f"{where}: its task reads channels {missing} of stream {stream!r}, "
                    f"which holds {channels}"
                )
            channels = [str(c) for c in chosen]
        rate = node.get("rate_hz")
        if (
            isinstance(rate, int | float)
            and spec.rate_hz
            and not math.isclose(float(rate), float(spec.rate_hz), rel_tol=1e-9)
        ):
            raise SlipkitError(
                f"{where}: rate_hz={rate:g} Hz, but stream {stream!r} of the family's "
                f"data is sampled at {spec.rate_hz:g} Hz (set "
                f"comparison.estimators.{est}.rate_hz={spec.rate_hz:g})"
            )
        width = node.get("n_channels")
        if isinstance(width, int) and width != len(channels):
            raise SlipkitError(
                f"{where}: n_channels={width}, but stream {stream!r} of the family's "
                f"data has {len(channels)} channel(s) (set "
                f"comparison.estimators.{est}.n_channels={len(channels)})"
            )


def comparison_seeds(cfg: DictConfig, comp: dict[str, Any]) -> list[int]:
    """The seeds a comparison runs: ``seeds=`` (command line), else the comparison's
    ``seeds:``, else the one ``seed``.

    Raises
    ------
    SlipkitError
        Not a non-empty list of whole numbers, or a seed listed twice.
    """
    key, given = "seeds", cfg.get("seeds")
    if given is None:
        key, given = "comparison.seeds", comp.get("seeds")
    if given is None:
        return [int(cfg.seed)]
    check_value(key, given, SEEDS)
    seeds = [int(s) for s in given]
    if len(set(seeds)) != len(seeds):
        raise SlipkitError(f"{key}={seeds}: a seed is listed twice")
    return seeds


def _seed_comparison(
    comp: dict[str, Any], seed: int, *, several: bool, data: Mapping[int, Any] | None
) -> dict[str, Any]:
    """The comparison as seed ``seed`` runs it: its data, split and training seed.

    ``data`` (seed -> dataset folder, e.g. the demo's simulated scenes) gives each
    seed its own folder. Otherwise, with several seeds, a simulated family draws its
    data with ``dataset.seed + seed`` (seed 0 reproduces the one-seed run); a
    dataset folder or a raw recording is the same for every seed (only the split
    and the training seed change).
    """
    out = dict(comp)
    dataset = dict(comp.get("dataset") or {})
    if data is not None and seed in data:
        dataset["path"] = str(data[seed])
    elif several and not dataset.get("path") and not dataset.get("raw"):
        dataset["seed"] = int(dataset.get("seed") or 0) + seed
    out["dataset"] = dataset
    return out


def run_comparison(
    cfg: DictConfig,
    folder: Path,
    *,
    progress: bool = True,
    data: Mapping[int, Any] | None = None,
) -> Comparison:
    """Run every estimator of ``cfg.comparison`` into ``folder`` and write the report there.

    With several seeds (:func:`comparison_seeds`), every estimator runs once per seed
    (its own data, split and training seed: :func:`_seed_comparison`) into
    ``runs/seed<s>/<estimator>``; the table holds the means over seeds with their
    spread (:func:`~slipkit.compare.table.seed_table`), ``seeds.csv`` every seed's
    row, and the verdict is taken on the means with the p99 of all seeds' decisions.

    Parameters
    ----------
    cfg : DictConfig
        A composed ``configs/compare.yaml``.
    folder : Path
        The output folder (exists, empty).
    progress : bool
        A tqdm bar over the runs.
    data : mapping of int to path, optional
        Seed -> the dataset folder that seed runs on (overrides ``comparison.dataset``).
    """
    from tqdm import tqdm

    start = time.perf_counter()
    comp = _container(cfg.comparison)
    estimators: dict[str, dict[str, Any]] = dict(comp.get("estimators") or {})
    if not estimators:
        raise SlipkitError(f"comparison {comp.get('name')!r} lists no estimators")
    seeds = comparison_seeds(cfg, comp)
    several = len(seeds) > 1
    # checked before anything trains: a typo in a limit must not cost a comparison
    limits = verdict_limits(comp.get("verdict"), "comparison.verdict")
    with quiet_console():
        check_estimators(
            _seed_comparison(comp, seeds[0], several=several, data=data), cfg
        )
    primary = str(comp.get("primary", "accuracy"))
    analytic = [str(a) for a in comp.get("analytic") or []]
    cost_cfg = _container(cfg.get("cost") or OmegaConf.create({}))
    keep = bool(cost_cfg.get("keep_bundles", False))
    per_seed: list[pd.DataFrame] = []
    evals: dict[str, Evaluation] = {}
    costs: dict[str, DeployCost] = {}
    summaries: dict[str, str] = {}
    pooled: dict[str, list[np.ndarray]] = {est: [] for est in estimators}
    unpaced: dict[str, list[np.ndarray]] = {est: [] for est in estimators}
    runs_of: dict[str, Path] = {}
    bar = tqdm(
        total=len(seeds) * len(estimators),
        desc=f"compare {comp['name']}",
        unit="run",
        disable=not progress,
    )
    for seed in seeds:
        comp_s = _seed_comparison(comp, seed, several=several, data=data)
        sub = Path("runs") / f"seed{seed}" if several else Path("runs")
        runs = folder / sub
        bundles = folder / "bundles" / (f"seed{seed}" if several else "")
        runs.mkdir(parents=True, exist_ok=True)
        rows: list[dict[str, Any]] = []
        splits: set[str] = set()
        for est, node in estimators.items():
            with quiet_console():
                row, ev, cost, summary = _run_one(
                    comp_s, est, node, cfg, runs, bundles, cost_cfg, analytic, seed
                )
            rows.append(row)
            splits.add(json.dumps(ev.split, sort_keys=True, default=str))
            if seed == seeds[0]:
                evals[est], costs[est], summaries[est] = ev, cost, summary
                runs_of[est] = sub / est
            if cost.exported:
                pooled[est].append(np.asarray(cost.latency_us, dtype=np.float64))
                unpaced[est].append(np.asarray(cost.unpaced_latency_us, np.float64))
            bar.update(1)
        if len(splits) != 1:
            raise SlipkitError(
                f"comparison {comp['name']!r}: the estimators' tasks recorded different "
                f"splits (seed {seed}); a comparison needs one split (same task settings "
                "and seed)"
            )
        per_seed.append(build_table(rows, primary).assign(seed=seed))
    bar.close()
    if not keep:
        import shutil

        shutil.rmtree(folder / "bundles", ignore_errors=True)
    seeds_df: pd.DataFrame | None = None
    if several:
        seeds_df = pd.concat(per_seed, ignore_index=True)
        seeds_df.to_csv(folder / "seeds.csv", index=False)
        lat = {e: np.concatenate(v) for e, v in pooled.items() if v}
        lat = {e: v for e, v in lat.items() if len(v)}  # a bundle may reach no decision
        df = seed_table(
            seeds_df,
            lat,
            primary,
            unpaced={e: np.concatenate(v) for e, v in unpaced.items() if v},
        )
        for est, c in costs.items():
            if est in lat and c.exported:
                # the latency plot shows what the verdict checked: all seeds' decisions
                c.latency_us = lat[est]
                c.p50_us = float(np.percentile(lat[est], 50))
                c.p99_us = block_p99(lat[est])
        split_note = (
            f"Each of {len(seeds)} seeds ({', '.join(map(str, seeds))}) ran every "
            "estimator on its own data, split and training seed; within a seed all "
            f"{len(evals)} estimators were scored on one identical split (checked). "
            "Scores are means over the seeds, shown as mean ± std; p99 is taken over "
            "all seeds' decisions (the median of 5 block p99s). Curves, ROC and "
            f"confusion plots are seed {seeds[0]}'s; `seeds.csv` has every seed's row."
        )
    else:
        df = per_seed[0].drop(columns="seed")
        split_note = (
            f"All {len(evals)} estimators were scored on one identical split (seed "
            f"{seeds[0]}; checked on the split each run recorded)."
        )
    df.to_csv(folder / "metrics.csv", index=False)
    made = {
        "pareto": plots.plot_pareto(
            df, primary, f"{comp['name']}: {primary} vs compute", folder / "pareto.png"
        ),
        "accuracy_vs_time": plots.plot_curves(
            evals, "vs_time", folder / "accuracy_vs_time.png"
        ),
        "accuracy_vs_width": plots.plot_curves(
            evals, "vs_width", folder / "accuracy_vs_width.png"
        ),
        "roc": plots.plot_roc(evals, folder / "roc.png"),
        "delays": plots.plot_delays(evals, folder / "delays.png"),
        "latency": plots.plot_latency(costs, folder / "latency.png"),
        "confusion": plots.plot_confusions(evals, folder / "confusion.png"),
        "search": plots.plot_search(evals, folder / "search_trials.png"),
    }
    config_yaml = OmegaConf.to_yaml(
        {k: v for k, v in _container(cfg).items() if k != "hydra"}
    )
    report = write_report(
        folder,
        name=str(comp["name"]),
        description=str(comp.get("description", "")),
        primary=primary,
        df=df,
        plots=made,
        command=_command(cfg),
        config_yaml=config_yaml,
        split_note=split_note,
        summaries=summaries,
        seconds=time.perf_counter() - start,
        verdict_limits=limits,
        cost=verdict_cost(comp.get("verdict")) if primary == "cost" else None,
    )
    return Comparison(folder, report, df, evals, costs, list(seeds), runs_of, seeds_df)


def compare_main(cfg: DictConfig) -> Path:
    """Run the comparison ``cfg.comparison``; print the report's path last and return it."""
    target = (
        Path(str(cfg.out))
        if cfg.get("out")
        else new_run_dir(Path(str(cfg.runs_dir)), str(cfg.name))
    )
    overwrite = bool(cfg.get("overwrite", False))
    data = cfg.comparison.get("dataset") or {}
    check_out_path(
        target,
        inputs={
            "comparison.dataset.path": data.get("path"),
            "comparison.dataset.raw": data.get("raw"),
        },
        option="out" if cfg.get("out") else "runs_dir",
        kind="comparison",
        overwrite=overwrite,
    )
    with atomic_dir(target, overwrite=overwrite, kind="comparison") as tmp:
        result = run_comparison(cfg, tmp, progress=bool(cfg.get("progress", True)))
    cols = ["estimator", "kind", "score", "p50_us", "p99_us", "export"]
    print(result.table[cols].to_string(index=False))
    report = target / "report.md"
    print(report)
    return report


__all__ = ["Comparison", "compare_main", "comparison_seeds", "run_comparison"]
