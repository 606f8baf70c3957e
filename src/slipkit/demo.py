"""``slipkit demo``: the README's main job, the whole pipeline on built-in defaults.

Stages, each with a progress bar and its wall time printed at the end:

1. **simulate** the scenes the comparisons use (each comparison's own size; one dataset
   per seed, scene seed ``dataset.seed + seed``) into ``<out>/data/<scene>-n<N>-s<seed>``;
2. **import** the public recordings a comparison reads, when they are present
   (``<out>/data/<source>``; ``import_all=true``: every one present);
3. **train + calibrate + compare** per sensor family (``configs/comparison``) over the
   demo's ``seeds``: the learned models are trained and the analytic baselines calibrated
   on the same split, exported and timed
   (:func:`slipkit.compare.commands.run_comparison`) into ``<out>/compare/<family>``;
   the verdict is taken on the means over the seeds;
4. **export** the verdict of each family (:func:`slipkit.compare.table.choose_deploy`:
   highest mean score among the exported ones whose p99 meets the budget; when none
   does, the best-scoring one, marked not recommended) to ``<out>/exports/<family>``
   (a family with none recommended: ``<out>/exports/not_recommended/<family>``);
5. **replay** that bundle's held-out test frames through the runtime loop
   (:class:`slipkit.runtime.StreamLoop`), paced at the sensor's rate, and judge its p99
   against the sensor's budget by the latency rule (:mod:`slipkit.runtime.budget`, as
   ``slipkit-run --check`` does), printing each bundle's status;
6. **closed loop**: every closed-loop scenario that exists (``configs/closedloop``,
   ``slipkit closedloop``), demo-sized, into ``<out>/closedloop/<scenario>``, with the
   verdict's own detector (:func:`closedloop_pick`): slip at arrest (mm) and drops (%);
   no detector (no verdict recommended, or one that decides no slip in a grasp): not run;
7. **report**: ``<out>/report.md`` opens with one row per family (:data:`FAMILY_HEADERS`:
   verdict, detection, false alarms, delay, slip mm, drop %, p99 against the budget, a
   note) and links each family's reports.

The report's path is printed last. ``quick=true`` shrinks every family (tiny data,
few epochs) for the tests.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
from hydra import compose
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from slipkit._files import (
    Layout,
    atomic_dir,
    atomic_write_text,
    check_out_path,
    first_line,
    manifest_kind,
)
from slipkit.data.io import load_dataset, save_dataset
from slipkit.errors import SlipkitError
from slipkit.runtime.budget import RULE_TEXT
from slipkit.sim.commands import build_scene

#: What the demo writes into ``out``, and nothing else: every stage below names its
#: entry from here, and an existing ``out`` holding only these (the report titled
#: :data:`REPORT_TITLE`) is an earlier demo, which the demo rewrites (:data:`LAYOUT`).
DATA, COMPARE, EXPORTS, CLOSEDLOOP, REPORT = (
    "data",
    "compare",
    "exports",
    "closedloop",
    "report.md",
)
#: where a family whose comparison recommends nothing gets its best candidate's bundle,
#: under ``exports/`` (so every bundle in ``exports/<family>`` is a recommended one)
NOT_RECOMMENDED = "not_recommended"
REPORT_TITLE = "# slipkit demo"
LAYOUT = Layout(
    "demo",
    frozenset({DATA, COMPARE, EXPORTS, CLOSEDLOOP, REPORT}),
    marks={
        **{name: Path.is_dir for name in (DATA, COMPARE, EXPORTS, CLOSEDLOOP)},
        REPORT: lambda path: first_line(path).startswith(REPORT_TITLE),
    },
)


def demo_seeds(cfg: DictConfig) -> list[int]:
    """The seeds every comparison runs: ``quick_seeds`` with ``quick=true``, else ``seeds``
    (each a non-empty list of distinct whole numbers)."""
    from slipkit._options import SEEDS, check_value

    key = "quick_seeds" if bool(cfg.get("quick", False)) else "seeds"
    given = cfg.get(key)
    if given is None:
        return [int(cfg.get("seed", 0))]
    check_value(key, given, SEEDS)
    seeds = [int(s) for s in given]
    if len(set(seeds)) != len(seeds):
        raise SlipkitError(f"{key}={seeds}: a seed is listed twice")
    return seeds


def _plan(cfg: DictConfig, present: dict[str, Path]) -> dict[str, DictConfig]:
    """Family -> its composed ``compare`` config (quick overrides applied; absent real data left out)."""
    quick = bool(cfg.get("quick", False))
    seeds = demo_seeds(cfg)
    plan: dict[str, DictConfig] = {}
    needs = dict(cfg.get("real_comparisons") or {})
    for family, extra in cfg.comparisons.items():
        family = str(family)
        if quick and family in list(cfg.get("quick_skip") or []):
            continue
        if family in needs and str(needs[family]) not in present:
            continue
        own = [str(o) for o in extra or []]
        overrides = [f"comparison={family}", *own]
        if not any(o.startswith(("seed=", "seeds=")) for o in own):
            overrides += [f"seed={seeds[0]}", f"seeds=[{','.join(map(str, seeds))}]"]
        if quick:
            overrides += [str(o) for o in (cfg.quick_overrides.get(family) or [])]
        frames = cfg.cost.quick_max_frames if quick else cfg.cost.max_frames
        overrides.append(f"cost.max_frames={int(frames)}")
        overrides.append(f"data_root={cfg.data_root}")
        plan[family] = compose(config_name="compare", overrides=overrides)
    return plan


def closedloop_plan(
    cfg: DictConfig, families: list[str]
) -> dict[str, tuple[str, list[str]]]:
    """Scenario -> (the family row it fills, its ``slipkit closedloop`` overrides).

    Every ``configs/closedloop/<scenario>.yaml`` that exists runs, demo-sized
    (``closedloop.seeds``, ``closedloop.trials_per_speed``, per-scenario overrides);
    ``closedloop.families`` maps a scenario to its family's row (default: the same
    name). A scenario whose family the demo does not compare is left out.
    """
    from slipkit import config_dir

    node = cfg.get("closedloop") or {}
    if not bool(node.get("enabled", True)):
        return {}
    quick = bool(cfg.get("quick", False))
    names = sorted(p.stem for p in (config_dir() / "closedloop").glob("*.yaml"))
    mapping = dict(node.get("families") or {})
    seeds = list(node.get("seeds") or [0])
    plan: dict[str, tuple[str, list[str]]] = {}
    for name in names:
        family = str(mapping.get(name, name))
        if family not in families:
            continue
        overrides = [
            f"closedloop={name}",
            f"seeds=[{','.join(str(int(s)) for s in seeds)}]",
            f"train_seed={int(node.get('train_seed', 0))}",
        ]
        for key in ("trials_per_speed", "train_trials", "warmup"):
            value = node.get(f"quick_{key}" if quick else key, node.get(key))
            if value is not None:
                overrides.append(f"{key}={int(value)}")
        per = node.get("quick_overrides" if quick else "overrides") or {}
        overrides += [str(o) for o in (per.get(name) or [])]
        plan[name] = (family, overrides)
    return plan


def _closedloop_row(summary: pd.DataFrame, shown: str) -> dict[str, Any]:
    """The summary row of detector ``shown`` (empty when it did not run: never another's)."""
    if summary.empty:
        return {}
    pick = summary[summary["detector"].astype(str) == str(shown)]
    if pick.empty:
        return {}
    return {str(k): v for k, v in pick.iloc[0].to_dict().items()}


def closedloop_pick(
    scenario: str,
    verdict: str,
    recommended: bool,
    detectors: list[str],
    shown: dict[str, Any],
) -> tuple[str | None, str]:
    """The scenario's detector that *is* the family's verdict, or None and why in a few words.

    ``shown`` maps a verdict estimator to its detector (``closedloop.detector.<scenario>``);
    else the detector named as the verdict. No verdict, a verdict not recommended, or a
    verdict without a detector (it cannot decide slip in a grasp): None, so the family's
    row never shows one detector's score beside another's grasp.

    Raises
    ------
    SlipkitError
        ``shown`` names a detector the scenario does not have.
    """
    if not verdict:
        return None, "no verdict: no closed loop"
    if not recommended:
        return None, "no closed loop: no detector recommended"
    pick = shown.get(verdict)
    if pick is not None:
        if str(pick) not in detectors:
            raise SlipkitError(
                f"closedloop.detector.{scenario}.{verdict}={pick}: not a detector of "
                f"configs/closedloop/{scenario}.yaml ({', '.join(detectors)})"
            )
        return str(pick), ""
    if verdict in detectors:
        return verdict, ""
    return None, f"no closed loop: {verdict} decides no slip in a grasp"


def _closedloop_detector(
    name: str,
    overrides: list[str],
    verdict: str,
    recommended: bool,
    shown: dict[str, Any],
    debounce_k: int | None = None,
) -> tuple[str | None, list[str], str]:
    """:func:`closedloop_pick` on the scenario's detectors, and the overrides that leave
    the others out (the demo runs the verdict's detector beside the oracle and
    no-detector bounds; ``slipkit closedloop scenario=<name>`` runs them all).

    ``debounce_k``: the deployed bundle's debounce (the comparison chose it on
    validation). The closed loop runs that operating point: the scenario's detector of
    the same run and export options with that debounce, else one added as
    ``<run>_k<debounce_k>``, so the row's grasp is the bundle's own.
    """
    node = compose(config_name="closedloop", overrides=overrides).closedloop
    dets = node.get("detectors") or {}
    names = [str(d) for d in dets]
    pick, why = closedloop_pick(name, verdict, recommended, names, shown)
    if pick is None:
        return None, [], why
    extra: list[str] = []
    if debounce_k is not None and int(dets[pick].get("debounce_k", 1)) != debounce_k:
        run = str(dets[pick].run)
        export = list(dets[pick].get("export") or [])
        same = [
            d
            for d in names
            if str(dets[d].run) == run
            and list(dets[d].get("export") or []) == export
            and int(dets[d].get("debounce_k", 1)) == debounce_k
        ]
        if same:
            pick = same[0]
        elif not export:
            pick = f"{run}_k{debounce_k}"
            extra = [
                f"+closedloop.detectors.{pick}={{run:{run},debounce_k:{debounce_k}}}"
            ]
        else:
            extra = [f"closedloop.detectors.{pick}.debounce_k={debounce_k}"]
    drop = [f"~closedloop.detectors.{d}" for d in names if d != pick]
    return pick, [*drop, *extra], ""


def _bundle_debounce(bundle: Path | None) -> int | None:
    """The debounce ``k`` an exported bundle deploys (None: no bundle)."""
    if bundle is None:
        return None
    manifest = json.loads((Path(bundle) / "manifest.json").read_text())
    return int((manifest.get("debounce") or {}).get("k", 1))


def _run_closedloop(
    cfg: DictConfig, name: str, overrides: list[str], out: Path
) -> pd.DataFrame:
    """``slipkit closedloop`` (its own function) into ``out``; its summary table."""
    from slipkit.closedloop.commands import closedloop_main

    ccfg = compose(
        config_name="closedloop",
        overrides=[*overrides, f"out={out}", "overwrite=true"],
    )
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        closedloop_main(ccfg)
    atomic_write_text(out.parent / f"{name}.log", buf.getvalue())
    return pd.read_csv(out / "summary.csv")


def export_dir(out: Path, family: str, *, recommended: bool) -> Path:
    """Where the demo writes a family's bundle: ``exports/<family>`` for a recommended
    verdict, ``exports/not_recommended/<family>`` for the best candidate of a family whose
    comparison recommends none (shown, never to be deployed)."""
    base = out / EXPORTS
    return base / family if recommended else base / NOT_RECOMMENDED / family


def clear_family_bundles(out: Path, family: str) -> list[Path]:
    """Remove the bundles an earlier demo into ``out`` left for ``family``, in
    ``exports/<family>`` and ``exports/not_recommended/<family>`` (with their
    ``.export.log``), so a family whose recommendation changed between runs keeps no
    bundle under the other verdict. Only slipkit bundles inside ``out`` are removed
    (never through a symbolic link); anything else at those paths is left for the
    export to refuse. Returns the removed folders."""
    removed = []
    root = out.resolve()
    for recommended in (True, False):
        where = export_dir(out, family, recommended=recommended)
        # a symbolic link on the way (the bundle or a folder above it) could lead out
        # of the demo's folder: left for the export to refuse
        inside = not where.is_symlink() and root in where.resolve().parents
        if inside and manifest_kind(where) == "bundle":
            shutil.rmtree(where)
            where.with_name(f"{where.name}.export.log").unlink(missing_ok=True)
            removed.append(where)
    return removed


def demo_main(cfg: DictConfig) -> Path:
    """Run the whole pipeline; print the index report's path last and return it."""
    from tqdm import tqdm

    start = time.perf_counter()
    stage_s: dict[str, float] = {}
    seeds = demo_seeds(cfg)  # a bad seed list is refused before anything is written
    out = Path(str(cfg.out))
    show = bool(cfg.get("progress", True))
    root = Path(str(cfg.data_root))
    present = {
        str(src): root / str(sub)
        for src, sub in cfg.real.items()
        if (root / str(sub)).exists()
    }
    # Only an earlier demo's output is rewritten; never the recordings it reads.
    check_out_path(
        out,
        inputs={f"real.{src}": path for src, path in present.items()},
        layout=LAYOUT,
        overwrite=bool(cfg.overwrite),
    )
    out.mkdir(parents=True, exist_ok=True)
    plan = _plan(cfg, present)
    datasets: list[dict[str, Any]] = []

    # 1. simulate: one dataset per (scene, size, scene seed) ----------------------------
    t_stage = time.perf_counter()
    scenes: dict[tuple[str, int, int], Path] = {}
    for ccfg in plan.values():
        comp = ccfg.comparison
        if comp.get("scene") is None:
            continue
        for s in seeds:
            key = (
                str(comp.scene.name),
                int(comp.dataset.n_trials),
                int(comp.dataset.seed) + s,
            )
            scenes.setdefault(key, out / DATA / f"{key[0]}-n{key[1]}-s{key[2]}")
    for (scene_name, n, seed), path in tqdm(
        list(scenes.items()), desc="1/7 simulate", unit="scene", disable=not show
    ):
        t0 = time.perf_counter()
        scene_cfg = compose(
            config_name="simulate", overrides=[f"scene={scene_name}"]
        ).scene
        dataset = build_scene(scene_cfg).simulate(
            n,
            seed,
            progress=False,
            config=OmegaConf.to_container(scene_cfg, resolve=True),
        )
        save_dataset(dataset, path, overwrite=bool(cfg.overwrite))
        datasets.append(_row(path, "simulated", time.perf_counter() - t0))
    data_of: dict[str, dict[int, Path]] = {}
    for family, ccfg in plan.items():
        comp = ccfg.comparison
        if comp.get("scene") is not None:
            data_of[family] = {
                s: scenes[
                    (
                        str(comp.scene.name),
                        int(comp.dataset.n_trials),
                        int(comp.dataset.seed) + s,
                    )
                ]
                for s in seeds
            }
    stage_s["simulate"] = time.perf_counter() - t_stage

    # 2. import ---------------------------------------------------------------------------
    t_stage = time.perf_counter()
    if not present:
        print(
            f"real recordings not found under {root} (set SLIPKIT_DATA); skipping the import "
            "stage and the real-data comparison"
        )
    imported: dict[str, Path] = {}
    # only the recordings a planned comparison reads (import_all=true: every one present)
    used = {
        str(src)
        for fam, src in (cfg.get("real_comparisons") or {}).items()
        if str(fam) in plan
    }
    to_import = {
        src: path
        for src, path in present.items()
        if bool(cfg.get("import_all", False)) or src in used
    }
    for source, src_path in tqdm(
        list(to_import.items()), desc="2/7 import", unit="source", disable=not show
    ):
        t0 = time.perf_counter()
        reader = instantiate(
            compose(
                config_name="import", overrides=[f"source={source}", "path=x", "out=x"]
            ).source
        )
        path = save_dataset(
            reader(src_path), out / DATA / source, overwrite=bool(cfg.overwrite)
        )
        imported[source] = path
        datasets.append(_row(path, "recorded", time.perf_counter() - t0))
    for family, source in (cfg.get("real_comparisons") or {}).items():
        if str(family) in plan and str(source) in imported:
            # recorded data: every seed reads the same recordings (split and training vary)
            data_of[str(family)] = {s: imported[str(source)] for s in seeds}
    stage_s["import"] = time.perf_counter() - t_stage

    # 3. train + calibrate + compare ------------------------------------------------------
    from slipkit.compare.commands import run_comparison

    t_stage = time.perf_counter()
    results = {}
    compare_s: dict[str, float] = {}
    for family, ccfg in tqdm(
        list(plan.items()),
        desc="3/7 train+calibrate+compare",
        unit="family",
        disable=not show,
    ):
        t0 = time.perf_counter()
        with atomic_dir(
            out / COMPARE / family, overwrite=True, kind="comparison"
        ) as tmp:
            results[family] = run_comparison(
                ccfg, tmp, progress=False, data=data_of.get(family)
            )
        results[family].folder = out / COMPARE / family
        results[family].report = results[family].folder / "report.md"
        compare_s[family] = time.perf_counter() - t0
    stage_s["compare"] = time.perf_counter() - t_stage

    # 4. export the verdict of each family ---------------------------------------------------
    from slipkit.compare.costs import export_run, time_bundle
    from slipkit.compare.report import closest_line
    from slipkit.compare.table import choose_deploy, verdict_limits

    t_stage = time.perf_counter()
    best: dict[str, dict[str, Any]] = {}
    exported: dict[str, Path] = {}
    for family, res in tqdm(
        list(results.items()), desc="4/7 export best", unit="family", disable=not show
    ):
        clear_family_bundles(out, family)
        # the comparison report's own rule (one function): within budget, else shown only
        # (and the comparison's verdict limits, e.g. the FSR disturbance rate)
        node = OmegaConf.to_container(plan[family].comparison, resolve=True)
        assert isinstance(node, dict)
        limits = verdict_limits(node.get("verdict"), f"comparison {family}: verdict")
        choice = choose_deploy(res.table, **limits)
        row = choice.row
        if row is None:
            continue
        best[family] = {str(k): v for k, v in row.to_dict().items()}
        best[family]["recommended"] = choice.recommended
        own = [w for e, w in choice.passed_over if e == str(row["estimator"])]
        if own:
            best[family]["why_not"] = own[-1]
        best[family]["primary"] = str(res.table.attrs.get("primary", ""))
        if not choice.recommended:
            best[family]["closest"] = closest_line(res.table, best[family]["primary"])
        if row["export"] != "ok":
            continue
        bundle = export_dir(out, family, recommended=choice.recommended)
        exported[family] = export_run(
            res.run_dir(str(row["estimator"])),
            bundle,
            max_frames=int(cfg.replay.max_frames),
        )
    stage_s["export"] = time.perf_counter() - t_stage

    # 5. replay the test data through the runtime loop -----------------------------------------
    t_stage = time.perf_counter()
    replay: dict[str, Any] = {}
    for family, bundle in tqdm(
        list(exported.items()), desc="5/7 replay", unit="bundle", disable=not show
    ):
        replay[family] = time_bundle(
            bundle, max_frames=int(cfg.replay.max_frames), warmup=int(cfg.replay.warmup)
        )
    for family, r in replay.items():
        # the latency rule's status, as slipkit-run --check prints it on this bundle
        print(f"replay {family}: {r.judgement.text()}")
    stage_s["replay"] = time.perf_counter() - t_stage

    # 6. closed loop: every scenario that exists, demo-sized ------------------------------------
    t_stage = time.perf_counter()
    loops = closedloop_plan(cfg, list(results))
    shown = dict((cfg.get("closedloop") or {}).get("detector") or {})
    closed: dict[str, dict[str, Any]] = {}
    loop_s: dict[str, float] = {}
    for name, (family, overrides) in tqdm(
        list(loops.items()), desc="6/7 closed loop", unit="scenario", disable=not show
    ):
        t0 = time.perf_counter()
        verdict_est = str(best.get(family, {}).get("estimator", ""))
        pick, drop, why = _closedloop_detector(
            name,
            overrides,
            verdict_est,
            bool(best.get(family, {}).get("recommended", False)),
            dict(shown.get(name) or {}),
            _bundle_debounce(exported.get(family)),
        )
        if pick is None:
            closed[family] = {"scenario": name, "why": why}
            loop_s[name] = time.perf_counter() - t0
            continue
        try:
            summary = _run_closedloop(
                cfg, name, [*overrides, *drop], out / CLOSEDLOOP / name
            )
        except SlipkitError as exc:
            # one scenario that cannot run (e.g. its detector's bundle fails the export
            # parity check) costs its row's closed-loop columns, not the whole demo
            print(f"slipkit demo: closed loop {name}: skipped: {exc}", file=sys.stderr)
            closed[family] = {
                "scenario": name,
                "why": f"closed loop {name} failed (see the demo's stderr)",
            }
            loop_s[name] = time.perf_counter() - t0
            continue
        shown_row = _closedloop_row(summary, pick)
        closed[family] = {"scenario": name, "ran": True, "detector": pick, **shown_row}
        if not shown_row:
            closed[family]["why"] = f"closed loop {name}: {pick} gave no result"
        loop_s[name] = time.perf_counter() - t0
    stage_s["closed loop"] = time.perf_counter() - t_stage

    # 7. report ---------------------------------------------------------------------------
    t_stage = time.perf_counter()
    with tqdm(total=1, desc="7/7 report", unit="file", disable=not show) as bar:
        stage_s["report"] = 0.0
        report = _write_index(
            out,
            results,
            best,
            exported,
            replay,
            closed,
            datasets,
            cfg,
            seeds,
            {**stage_s, "total": time.perf_counter() - start},
            {
                **{f"compare {k}": v for k, v in compare_s.items()},
                **{f"closed loop {k}": v for k, v in loop_s.items()},
            },
        )
        bar.update(1)
    stage_s["report"] = time.perf_counter() - t_stage
    print("\n" + _table(datasets))
    print()
    print(family_table_text(results, best, closed))
    print()
    print(stage_text({**stage_s, "total": time.perf_counter() - start}))
    print(report)
    return report


def _fmt(v: Any, spec: str = "{:.3g}") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    return (
        spec.format(v)
        if isinstance(v, int | float) and not isinstance(v, bool)
        else str(v)
    )


def _pm(row: dict[str, Any], key: str, spec: str) -> str:
    """``row[key]`` as ``mean ± std`` (std when finite), ``-`` when missing."""
    mean = _fmt(row.get(key), spec)
    if not mean:
        return "-"
    std = _fmt(row.get(f"{key}_std"), spec)
    return f"{mean} ± {std}" if std else mean


#: the family table's headers (the demo report's first screen)
FAMILY_HEADERS = (
    "family",
    "verdict",
    "detection",
    "false alarms",
    "delay (ms)",
    "slip at arrest (mm)",
    "dropped (%)",
    "p99 / budget (us)",
    "note",
)

#: primary metrics shown as a percentage, and their name on the first screen
_PERCENT = {
    "accuracy": "accuracy",
    "balanced_accuracy": "balanced accuracy",
    "detected_rate": "detected",
    "on_time_rate": "on time",
    "tpr": "TPR",
    "tnr": "TNR",
    "sequence_accuracy": "sequence accuracy",
}
#: other primary metrics' names on the first screen (the rest: the column's own name)
_NAMES = {"rmse": "RMSE", "smse": "SMSE", "f1": "F1", "roc_auc": "ROC AUC"}


def _pm_sig(row: dict[str, Any], key: str, digits: int = 3) -> str:
    """``row[key]`` to ``digits`` significant digits, its std to the same decimals
    (``0.231 ± 0.006``, ``17.0 ± 1.4``, ``190 ± 22``); ``-`` when missing."""
    mean = row.get(key)
    if not isinstance(mean, int | float) or isinstance(mean, bool):
        return "-"
    if not math.isfinite(mean):
        return "-"
    size = math.floor(math.log10(abs(mean))) if mean else 0
    decimals = max(digits - 1 - size, 0)
    return _pm(row, key, f"{{:.{decimals}f}}")


def _pct(row: dict[str, Any], key: str) -> str:
    """``row[key]`` (a fraction) as ``97 ± 3 %``; "" when missing."""
    scaled = {
        k: 100.0 * float(row[k])
        for k in (key, f"{key}_std")
        if isinstance(row.get(k), int | float) and not isinstance(row.get(k), bool)
    }
    text = _pm(scaled, key, "{:.0f}")
    return "" if text == "-" else f"{text} %"


def detection_cell(row: dict[str, Any]) -> str:
    """The verdict's primary metric with its name and unit (mean ± std over seeds):
    ``RMSE 0.250 ± 0.020 N``, ``accuracy 91 ± 2 %``, ``cost 0.120 ± 0.030 (detected 97 %)``
    (the trial cost is in missed slips per trial)."""
    from slipkit.compare.table import metric_unit

    primary = str(row.get("primary", ""))
    if not primary or row.get(primary) is None:
        return "-"
    if primary in _PERCENT:
        text = _pct(row, primary)
        return f"{_PERCENT[primary]} {text}" if text else "-"
    value = _pm_sig(row, primary)
    if value == "-":
        return "-"
    unit = metric_unit(primary, list(row))
    text = f"{_NAMES.get(primary, primary)} {value}" + (f" {unit}" if unit else "")
    detected = _pct(row, "detected_rate")
    return f"{text} (detected {detected})" if detected else text


def false_alarm_cell(row: dict[str, Any]) -> str:
    """The verdict's false alarms as its comparison reports them: the share of test trials
    with an early alarm and / or alarms per minute of non-slip time; ``-`` when neither."""
    parts = []
    early = _pct(row, "early_alarm_rate")
    if early:
        parts.append(f"early in {early} of trials")
    per_min = _pm_sig(row, "false_alarms_per_min", 2)
    if per_min != "-":
        parts.append(f"{per_min} /min")
    return "; ".join(parts) or "-"


def budget_cell(row: dict[str, Any]) -> str:
    """``p99 / budget (ratio)`` with the latency rule's word when not plainly within."""
    from slipkit.runtime.budget import judge_p99

    p99 = float(row.get("p99_us", math.nan))
    budget = float(row.get("budget_p99_us", math.nan))
    if math.isfinite(p99) and math.isfinite(budget) and budget > 0:
        status = judge_p99(p99, budget).status
        word = "" if status == "within" else f", {status}"
        return f"{p99:.1f} / {budget:.4g} ({p99 / budget:.2f}x{word})"
    check = str(row.get("export", "-")) or "-"
    return check if len(check) <= 40 else check[:37] + "..."


def family_rows(
    results: dict[str, Any],
    best: dict[str, dict[str, Any]],
    closed: dict[str, dict[str, Any]],
) -> list[tuple[str, ...]]:
    """One row per family (:data:`FAMILY_HEADERS`): the verdict, its primary metric, false
    alarms and delay (mean ± std over seeds), slip at arrest and drop rate of the *same*
    detector in the family's closed-loop scenario, its p99 against the budget, and a note:
    the closed-loop detector shown, or why there is none / no verdict.

    The closed-loop columns are ``-`` unless ``closed[family]`` holds the verdict's own
    detector (``closed[family]["ran"]``, as :func:`demo_main` fills it)."""
    rows: list[tuple[str, ...]] = []
    for family in results:
        b = best.get(family, {})
        c = closed.get(family, {})
        est = str(b.get("estimator", ""))
        recommended = bool(b.get("recommended", False))
        ran = bool(c.get("ran")) and "why" not in c and recommended
        if not b:
            verdict, note = "-", "no estimator to rank"
        elif not recommended:
            verdict = f"none (best: {est})"
            note = f"{est}: {b.get('why_not', 'see its report')}"
        else:
            verdict = est
            if ran:
                note = f"closed loop {c['scenario']}: {c.get('detector', est)}"
            elif c:
                note = str(c.get("why", "no closed loop"))
            else:
                note = "no closed-loop scenario"
        rows.append(
            (
                family,
                verdict,
                detection_cell(b) if b else "-",
                false_alarm_cell(b) if b else "-",
                _pm(b, "delay_ms", "{:.1f}"),
                _pm(c, "slip_mm", "{:.1f}") if ran else "-",
                _pm(c, "dropped_pct", "{:.0f}") if ran else "-",
                budget_cell(b) if b else "-",
                note,
            )
        )
    return rows


def family_table(
    results: dict[str, Any],
    best: dict[str, dict[str, Any]],
    closed: dict[str, dict[str, Any]],
) -> list[str]:
    """The family table in Markdown."""
    return [
        "| " + " | ".join(FAMILY_HEADERS) + " |",
        "|" + "---|" * len(FAMILY_HEADERS),
        *("| " + " | ".join(r) + " |" for r in family_rows(results, best, closed)),
    ]


def family_table_text(
    results: dict[str, Any],
    best: dict[str, dict[str, Any]],
    closed: dict[str, dict[str, Any]],
) -> str:
    """The family table as fixed-width text (what the command prints)."""
    rows = family_rows(results, best, closed)
    return pd.DataFrame(rows, columns=list(FAMILY_HEADERS)).to_string(index=False)


def stage_text(stage_s: dict[str, float]) -> str:
    """``stage times (s): simulate 3.1 | import 0.0 | ... | total 212.4``."""
    return "stage times (s): " + " | ".join(f"{k} {v:.1f}" for k, v in stage_s.items())


def not_recommended_lines(best: dict[str, dict[str, Any]]) -> list[str]:
    """Under the family table, one line per family that recommends nothing on latency:
    its comparison report's row nearest the budget and what would make it fit."""
    lines = [f"- {f}: {b['closest']}" for f, b in best.items() if b.get("closest")]
    return ["", *lines] if lines else []


def _write_index(
    out: Path,
    results: dict[str, Any],
    best: dict[str, dict[str, Any]],
    exported: dict[str, Path],
    replay: dict[str, Any],
    closed: dict[str, dict[str, Any]],
    datasets: list[dict[str, Any]],
    cfg: DictConfig,
    seeds: list[int],
    stage_s: dict[str, float],
    detail_s: dict[str, float],
) -> Path:
    n = len(seeds)
    lines = [
        f"{REPORT_TITLE}: which detector to deploy for each sensor",
        "",
        *family_table(results, best, closed),
        *not_recommended_lines(best),
        "",
        f"Verdict: the highest mean score over {n} seed{'s' if n > 1 else ''} "
        f"({', '.join(map(str, seeds))}) among the estimators whose bundle exports and "
        "whose p99 per frame (the median of 5 block p99s over every seed's timed decisions, "
        "onnxruntime, 1 thread, batch 1) meets the sensor's budget; each family's report "
        "says why the higher-scoring ones were passed over (`none`: no estimator passes; "
        "the numbers are then the best-scoring one's, the note says why). Detection: the "
        "family's primary metric with its unit (a trial cost is in missed slips per trial, "
        "with the share of slips detected); false alarms: the share of test trials with an "
        "alarm before the slip and / or alarms per minute of non-slip time; delay: median "
        "detection delay; all mean ± std over the seeds. Slip at arrest (caught objects) "
        "and dropped objects: `slipkit closedloop` on the family's scenario (demo-sized: "
        f"{_closedloop_size(cfg)}) with the verdict's own detector deciding through its "
        "bundle in the runtime loop (named in the note); `-` with the reason in the note "
        "when there is none. p99 / budget: `borderline` or `over` by the latency rule.",
        "",
        f"Made by `slipkit demo{' quick=true' if cfg.get('quick') else ''}` in "
        f"{stage_s.get('total', math.nan):.0f} s; {stage_text(stage_s)}.",
        "",
        "## Deployed bundles",
        "",
        "The verdict of each family exported to an ONNX bundle (first seed's run) and its "
        "held-out test frames replayed through the runtime loop, paced at the sensor's "
        "rate, against the sensor's budget. " + RULE_TEXT,
        "",
        "| family | deploy | kind | replay p50 (us) | replay p99 (us) | p99 budget (us) | latency | bundle | report |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for family in results:
        b = best.get(family, {})
        r = replay.get(family)
        where = export_dir(Path(), family, recommended=bool(b.get("recommended")))
        bundle = (
            f"[{where.as_posix()}]({where.as_posix()})"
            if family in exported
            else str(b.get("export", ""))
        )
        lines.append(
            "| "
            + " | ".join(
                [
                    family,
                    f"`{b.get('estimator', '-')}`"
                    + ("" if b.get("recommended", True) else " (not recommended)"),
                    str(b.get("kind", "")),
                    _fmt(None if r is None else r.p50_us, "{:.1f}"),
                    _fmt(None if r is None else r.p99_us, "{:.1f}"),
                    _fmt(None if r is None else r.budget_p99_us, "{:.4g}"),
                    "" if r is None else r.judgement.status,
                    bundle,
                    f"[compare/{family}/report.md](compare/{family}/report.md)",
                ]
            )
            + " |"
        )
    if any(c.get("ran") for c in closed.values()):
        lines += ["", "Closed-loop reports: "]
        lines[-1] += ", ".join(
            f"[{c['scenario']}](closedloop/{c['scenario']}/report.md)"
            for c in closed.values()
            if c.get("ran")
        )
    lines += _controls_section(best)
    lines += ["", "## Accuracy against compute, per family", ""]
    for family, res in results.items():
        png = res.folder / "pareto.png"
        if png.is_file():
            lines += [
                f"### {family}",
                "",
                f"![{family}](compare/{family}/pareto.png)",
                "",
            ]
    lines += ["## Datasets", "", "```", _table(datasets), "```", ""]
    lines += [
        "## Time per family (s)",
        "",
        "```",
        "\n".join(f"{k:<34}{v:>8.1f}" for k, v in detail_s.items()),
        "```",
        "",
    ]
    path = out / REPORT
    atomic_write_text(path, "\n".join(lines))
    return path


def _closedloop_size(cfg: DictConfig) -> str:
    node = cfg.get("closedloop") or {}
    quick = bool(cfg.get("quick", False))
    seeds = [str(int(x)) for x in node.get("seeds") or [0]]
    tps = node.get("quick_trials_per_speed" if quick else "trials_per_speed")
    trials = "the scenario's" if tps is None else str(int(tps))
    return (
        f"seed{'s' if len(seeds) > 1 else ''} {', '.join(seeds)}, "
        f"{trials} trial{'' if trials == '1' else 's'} per condition"
    )


#: (row column, header) of the controls beside a window classifier's headline
_CONTROLS = (
    ("accuracy", "per window"),
    ("balanced_accuracy", "balanced"),
    ("sequence_accuracy", "per sequence (vote)"),
    ("first_frame_accuracy", "first frame only"),
    ("dynamics_accuracy", "dynamics only"),
    ("majority_accuracy", "majority class"),
)


def _controls_section(best: dict[str, dict[str, Any]]) -> list[str]:
    """The controls of each family whose best estimator reports them (window tasks)."""
    rows = []
    for family, b in best.items():
        if not any(
            isinstance(b.get(c), float) and math.isfinite(b[c])
            for c, _ in _CONTROLS[2:]
        ):
            continue
        rows.append(
            f"| {family} | `{b.get('estimator', '-')}` | "
            + " | ".join(_fmt(b.get(c), "{:.3f}") for c, _ in _CONTROLS)
            + " |"
        )
    if not rows:
        return []
    return [
        "",
        "## Controls beside the headline (window classifiers)",
        "",
        "The deployed estimator per window and per sequence, beside the same model fitted on "
        "each trial's first frame only (static contact), on dynamics only (each trial's first "
        "frame subtracted), and the training side's majority class.",
        "",
        "| family | deploy | " + " | ".join(h for _, h in _CONTROLS) + " |",
        "|---|---|" + "---|" * len(_CONTROLS),
        *rows,
    ]


def _row(path: Path, origin: str, seconds: float) -> dict[str, Any]:
    dataset = load_dataset(path)
    return {
        "dataset": path.name,
        "origin": origin,
        "sensor": dataset.sensor,
        "trials": len(dataset),
        "rows": sum(len(t) for t in dataset.tables.values()),
        "seconds": seconds,
        "path": path,
    }


def _table(rows: list[dict[str, Any]]) -> str:
    head = f"{'dataset':<34}{'origin':<11}{'sensor':<14}{'trials':>7}{'rows':>11}{'time (s)':>10}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['dataset']:<34}{r['origin']:<11}{r['sensor']:<14}{r['trials']:>7}{r['rows']:>11}{r['seconds']:>10.2f}"
        )
    return "\n".join(lines)
