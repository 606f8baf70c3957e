"""``slipkit closedloop scenario=<family>``: what a detector's accuracy costs a grasp.

Composes ``configs/closedloop.yaml``; the scenario file ``configs/closedloop/<family>.yaml``
names the scene (plant parameters and sensor effects), the controller and actuator, the
conditions (TacTip: retraction speeds), the detectors and the runs they come from; the
family's plant, sensor mapping, controller and trial drawing are its registered scenario
(:mod:`slipkit.closedloop.scenarios`; ``family:`` in the file, default its ``name``). For each run the command trains the
detector with ``slipkit train``'s own function on the family's experiment (once per
command run, kept under ``<out>/runs/``), exports it with ``slipkit export``'s function
once per debounce (``<out>/bundles/``), and runs every trial with the bundle deciding
frame by frame through :class:`slipkit.runtime.StreamLoop`. A zero-delay oracle and a
no-detector run bound the table; an oracle with a fixed added delay traces the plant's
own slip-versus-delay curve. The output folder (written atomically) holds
``results.csv`` (one row per trial), ``summary.csv`` (one row per detector),
``report.md`` and the headline plot; the report's path is printed last.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd
from omegaconf import DictConfig, ListConfig, OmegaConf

from slipkit._files import atomic_dir, check_out_path
from slipkit._options import (
    COUNT,
    FLAG,
    SEED,
    check_options,
    check_value,
    whole,
    within,
)
from slipkit.closedloop.detectors import (
    BundleDetector,
    Detector,
    NoDetector,
    OracleDetector,
)
from slipkit.closedloop.report import markdown_table, summarize, write_report
from slipkit.closedloop.run import run_detector
from slipkit.closedloop.scenarios import (
    ClosedLoopScenario,
    get_scenario,
    plant_params,
)
from slipkit.errors import SlipkitError
from slipkit.train.runs import new_run_dir

log = logging.getLogger("slipkit.closedloop")


def _compose(name: str, overrides: list[str], where: str = "") -> DictConfig:
    """``configs/<name>.yaml`` with ``overrides`` (from the scenario file: ``where`` names the
    field); a config that does not compose is a one-line SlipkitError naming it."""
    from hydra import compose
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    try:
        return compose(config_name=name, overrides=overrides)
    except (HydraException, OmegaConfBaseException) as exc:
        from slipkit._options import composition_message, one_line

        text = one_line(composition_message(exc))
        raise SlipkitError(f"{where or name}: {text}") from None


#: Declared ranges of a scenario's own options (configs/closedloop/<family>.yaml)
TRIALS_PER_SPEED = whole(1, 1000)
TRAIN_TRIALS = whole(1, 10_000)
ORACLE_DELAY_MS = within(0.0, 1000.0, "ms")


def check_scenario_options(scen: DictConfig) -> None:
    """Refuse a scenario option outside its declared range, naming it."""
    for key, rule in (
        ("trials_per_speed", TRIALS_PER_SPEED),
        ("train_trials", TRAIN_TRIALS),
    ):
        check_value(f"closedloop.{key}", scen.get(key), rule)
    delays = scen.get("oracle_delays_ms") or []
    if not isinstance(delays, ListConfig | list):
        raise SlipkitError(
            f"closedloop.oracle_delays_ms={delays}: expected a list of delays in ms, e.g. [10, 25]"
        )
    for i, delay in enumerate(delays):
        check_value(f"closedloop.oracle_delays_ms[{i}]", delay, ORACLE_DELAY_MS)
    if not isinstance(scen.get("plant"), DictConfig):
        raise SlipkitError(
            f"closedloop.plant={scen.get('plant')}: expected a mapping of plant parameters"
        )


def load_scenario(cfg: DictConfig) -> DictConfig:
    """The scenario: ``cfg.closedloop``, or ``configs/closedloop/<cfg.scenario>.yaml`` when
    ``scenario=`` names another family; the top-level knobs applied."""
    from slipkit import config_dir

    name = str(cfg.scenario)
    available = sorted(p.stem for p in (config_dir() / "closedloop").glob("*.yaml"))
    if name not in available:
        raise SlipkitError(
            f"scenario={name}: no closed-loop scenario for it; available: {', '.join(available)}"
        )
    node = cfg.get("closedloop")
    if node is None or str(node.get("name")) != name:
        if node is not None:
            # cfg holds another scenario: overrides of it would be dropped silently
            other = str(node.get("name"))
            unchanged = _compose("closedloop", [f"closedloop={other}"]).closedloop
            if OmegaConf.to_container(node) != OmegaConf.to_container(unchanged):
                raise SlipkitError(
                    f"scenario={name}: the closedloop.* overrides apply to scenario "
                    f"{other}; give closedloop={name} with them"
                )
        node = _compose(
            "closedloop", [f"closedloop={name}"], f"scenario={name}"
        ).closedloop
    plain = OmegaConf.to_container(node, resolve=True)
    if not isinstance(plain, dict):
        raise SlipkitError(f"configs/closedloop/{name}.yaml: expected a mapping")
    scen = OmegaConf.create(plain)
    demo = cfg.get("demo", False)
    check_value("demo", demo, FLAG)
    if demo:
        apply_demo(scen, name)
    for key in ("trials_per_speed", "train_trials"):
        if cfg.get(key) is not None:
            scen[key] = int(cfg[key])
    check_scenario_options(scen)
    return scen


def apply_demo(scen: DictConfig, name: str) -> None:
    """Shrink ``scen`` to its ``demo:`` block (in place): trials, training trials, detectors, delays.

    ``demo.detectors`` lists the detectors kept (each must be one of ``detectors``);
    the runs no kept detector uses are not trained.
    """
    block = scen.get("demo")
    if block is None:
        raise SlipkitError(
            f"demo=true: configs/closedloop/{name}.yaml has no demo: block"
        )
    for key in ("trials_per_speed", "train_trials"):
        if block.get(key) is not None:
            check_value(f"configs/closedloop/{name}.yaml demo.{key}", block[key], COUNT)
            scen[key] = int(block[key])
    if block.get("oracle_delays_ms") is not None:
        scen["oracle_delays_ms"] = list(block.oracle_delays_ms)
    keep = block.get("detectors")
    if keep is not None:
        known = scen.get("detectors") or {}
        missing = [str(d) for d in keep if str(d) not in known]
        if missing:
            raise SlipkitError(
                f"configs/closedloop/{name}.yaml demo.detectors: {missing} not among "
                f"detectors ({', '.join(map(str, known))})"
            )
        scen["detectors"] = {str(d): known[str(d)] for d in keep}


def scenario_of(scen: DictConfig) -> ClosedLoopScenario:
    """The registered scenario of ``scen`` (its ``family``, default its ``name``)."""
    return get_scenario(str(scen.get("family") or scen.name))


def _command(cfg: DictConfig) -> str:
    from hydra.core.hydra_config import HydraConfig

    if HydraConfig.initialized():
        return " ".join(["slipkit closedloop", *HydraConfig.get().overrides.task])
    return str(cfg.get("command") or "slipkit closedloop " + " ".join(sys.argv[1:]))


def _quiet(fn: Any, *args: Any) -> tuple[Any, str]:
    """Call ``fn(*args)`` with its printout (stdout and stderr) captured and ``slipkit.*`` logs off the console."""
    buf = io.StringIO()
    logger = logging.getLogger("slipkit")
    saved = logger.propagate
    logger.propagate = False
    try:
        # stderr too: the task's progress lines would interleave with the command's.
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
            out = fn(*args)
    finally:
        logger.propagate = saved
    return out, buf.getvalue()


def train_run(spec: Mapping[str, Any], n_trials: int, seed: int, run_dir: Path) -> Path:
    """Train one detector with ``slipkit train``'s function: ``experiment=<spec.experiment>``."""
    from slipkit.train.commands import train_main

    overrides = [
        f"experiment={spec['experiment']}",
        f"dataset.n_trials={int(n_trials)}",
        f"seed={int(seed)}",
        f"run_dir={run_dir}",
        *[str(o) for o in spec.get("overrides") or []],
    ]
    tcfg = _compose("train", overrides, f"closedloop.runs.{run_dir.name}")
    _, text = _quiet(train_main, tcfg)
    (run_dir.parent / f"{run_dir.name}.train.log").write_text(text)
    return run_dir


def export_bundle(
    run: Path, out: Path, debounce_k: int, overrides: Sequence[str] = ()
) -> Path:
    """Export ``run`` with ``slipkit export``'s function, declaring slip after ``debounce_k`` frames.

    ``overrides``: further ``slipkit export`` options (a detector's ``export:`` list,
    e.g. ``regression.threshold=10`` for a SlipTack speed graph).
    """
    from slipkit.export.commands import export_main

    ecfg = _compose(
        "export",
        [
            f"run={run}",
            f"out={out}",
            f"debounce_k={int(debounce_k)}",
            "choose_session=false",
            "replay_max_frames=200",
            "parity.max_calls=5000",
            *[str(o) for o in overrides],
        ],
        f"closedloop.detectors.{out.name}.export",
    )
    path, text = _quiet(export_main, ecfg)
    (out.parent / f"{out.name}.export.log").write_text(text)
    return Path(path)


def _run_metrics(run: Path) -> dict[str, float]:
    """The run's held-out per-frame accuracy and balanced accuracy (%).

    A frame classifier's ``test.accuracy`` / ``test.balanced_accuracy``; a stream
    detector's from its per-sample counts (``test.samples``: tp, fn, fp, tn).
    """
    metrics = json.loads((run / "metrics.json").read_text())
    test = metrics.get("test", {})
    if "accuracy" not in test and isinstance(test.get("samples"), dict):
        c = test["samples"]
        try:
            tp, fn, fp, tn = (float(c[k]) for k in ("tp", "fn", "fp", "tn"))
        except (KeyError, TypeError, ValueError):
            tp = fn = fp = tn = math.nan
        n = tp + fn + fp + tn
        tpr = tp / (tp + fn) if tp + fn > 0 else math.nan
        tnr = tn / (tn + fp) if tn + fp > 0 else math.nan
        return {
            "accuracy_pct": 100.0 * (tp + tn) / n if n > 0 else math.nan,
            "balanced_accuracy_pct": 50.0 * (tpr + tnr),
        }
    return {
        "accuracy_pct": 100.0 * float(test.get("accuracy", math.nan)),
        "balanced_accuracy_pct": 100.0 * float(test.get("balanced_accuracy", math.nan)),
    }


def build_detectors(
    scen: DictConfig, folder: Path, *, warmup: int, seed: int
) -> tuple[list[Detector], dict[str, dict[str, Any]]]:
    """Train, export and load every detector of the scenario; the bounds last.

    Returns the detectors and, per name, what the table shows beside the outcomes
    (kind, debounce, accuracy, budget).
    """
    runs: dict[str, Path] = {}
    info: dict[str, dict[str, Any]] = {}
    detectors: list[Detector] = []
    for name, node in (scen.get("detectors") or {}).items():
        run_name = str(node.run)
        if run_name not in (scen.get("runs") or {}):
            raise SlipkitError(
                f"closedloop.detectors.{name}.run={run_name}: not one of closedloop.runs "
                f"({', '.join(map(str, scen.get('runs') or {}))})"
            )
        if run_name not in runs:
            start = time.perf_counter()
            runs[run_name] = train_run(
                scen.runs[run_name],
                int(scen.train_trials),
                seed,
                folder / "runs" / run_name,
            )
            log.info("trained %s in %.1f s", run_name, time.perf_counter() - start)
        k = int(node.debounce_k)
        check_value(f"closedloop.detectors.{name}.debounce_k", k, COUNT)
        bundle = export_bundle(
            runs[run_name],
            folder / "bundles" / str(name),
            k,
            [str(o) for o in node.get("export") or []],
        )
        det = BundleDetector(bundle, str(name), warmup=warmup)
        detectors.append(det)
        info[str(name)] = {
            "kind": "bundle",
            "run": run_name,
            "debounce_k": det.debounce_k,
            "p99_budget_us": det.p99_budget_us,
            **_run_metrics(runs[run_name]),
        }
    detectors.append(OracleDetector("oracle"))
    info["oracle"] = {"kind": "oracle", "accuracy_pct": 100.0}
    detectors.append(NoDetector("none"))
    info["none"] = {"kind": "none"}
    for delay_ms in scen.get("oracle_delays_ms") or []:
        name = f"oracle+{float(delay_ms):g}ms"
        detectors.append(OracleDetector(name, delay_s=float(delay_ms) / 1e3))
        info[name] = {"kind": "delayed oracle", "added_delay_ms": float(delay_ms)}
    return detectors, info


def run_scenario(
    cfg: DictConfig, scen: DictConfig, folder: Path
) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """Every detector over every seed, speed and trial; (results, summary, timings)."""
    from slipkit.sim.commands import build_scene

    seeds = [int(s) for s in cfg.seeds]
    for i, s in enumerate(seeds):
        check_value(f"seeds[{i}]", s, SEED)
    if not seeds:
        raise SlipkitError("seeds=[]: list at least one seed")
    plant = plant_params(scen)
    scenario = scenario_of(scen)
    scene_cfg = _compose(
        "train",
        [f"scene={scen.scene}", *[str(o) for o in scen.get("scene_overrides") or []]],
        f"closedloop.scene={scen.scene}",
    ).scene
    scene = build_scene(scene_cfg)
    scenario.check(scen, scene)
    conditions = scenario.conditions(scen)
    start = time.perf_counter()
    detectors, info = build_detectors(
        scen, folder, warmup=int(cfg.warmup), seed=int(cfg.train_seed)
    )
    timings: dict[str, Any] = {"prepare_s": time.perf_counter() - start, "loop_s": {}}
    rows: list[dict[str, Any]] = []
    latencies: dict[str, Any] = {}
    for det in detectors:
        t0 = time.perf_counter()
        outcomes = run_detector(
            scenario,
            scene,
            det,
            plant,
            seeds=seeds,
            conditions=conditions,
            trials_per_condition=int(scen.trials_per_speed),
        )
        timings["loop_s"][det.name] = time.perf_counter() - t0
        rows.extend(o.row() for o in outcomes)
        latencies[det.name] = det.latency_us()
    results = pd.DataFrame(rows)
    summary = summarize(results, info, latencies)
    timings["conditions"] = conditions
    timings["condition_label"] = scenario.condition_label
    return results, summary, timings


def closedloop_main(cfg: DictConfig) -> Path:
    """Run the scenario ``cfg.scenario``; write the output folder; print its report's path last."""
    check_options(cfg, "closedloop")  # also run by the CLI; here for direct calls
    scen = load_scenario(cfg)
    out = (
        Path(str(cfg.out))
        if cfg.get("out")
        else new_run_dir(Path(str(cfg.runs_dir)) / "closedloop", str(cfg.scenario))
    )
    check_out_path(out, kind="closedloop", overwrite=bool(cfg.overwrite))
    start = time.perf_counter()
    with atomic_dir(out, overwrite=bool(cfg.overwrite), kind="closedloop") as tmp:
        results, summary, timings = run_scenario(cfg, scen, tmp)
        timings["total_s"] = time.perf_counter() - start
        results.to_csv(tmp / "results.csv", index=False)
        summary.to_csv(tmp / "summary.csv", index=False)
        write_report(
            tmp,
            scenario=scen,
            results=results,
            summary=summary,
            timings=timings,
            command=_command(cfg),
            seeds=[int(s) for s in cfg.seeds],
        )
    report = out / "report.md"
    print(markdown_table(summary))
    print(report)
    return report
