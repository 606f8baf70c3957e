"""``slipkit demo``: the README's main job, the whole pipeline on built-in defaults.

Stages, each with a progress bar:

1. **simulate** the scenes the comparisons use (each comparison's own size and seed)
   into ``<out>/data/<scene>``;
2. **import** the public recordings when they are present (``<out>/data/<source>``);
3. **train + calibrate + compare** per sensor family (``configs/comparison``): the
   learned models are trained and the analytic baselines calibrated on the same split,
   exported and timed (:func:`slipkit.compare.commands.run_comparison`) into
   ``<out>/compare/<family>``;
4. **export** the best estimator of each family (the comparison's verdict,
   :func:`slipkit.compare.table.choose_deploy`: highest score among the exported ones whose
   p99 meets the budget; when none does, the best-scoring one, marked not recommended)
   to ``<out>/exports/<family>``;
5. **replay** that bundle's held-out test frames through the runtime loop
   (:class:`slipkit.runtime.StreamLoop`) against the sensor's budget;
6. **report**: ``<out>/report.md`` indexes each family's comparison report.

The report's path is printed last. ``quick=true`` shrinks every family (tiny data,
few epochs) for the tests.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

from hydra import compose
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from slipkit._files import atomic_dir, atomic_write_text, check_out_path
from slipkit.data.io import load_dataset, save_dataset
from slipkit.sim.commands import build_scene


def _plan(cfg: DictConfig, present: dict[str, Path]) -> dict[str, DictConfig]:
    """Family -> its composed ``compare`` config (quick overrides applied; absent real data left out)."""
    quick = bool(cfg.get("quick", False))
    plan: dict[str, DictConfig] = {}
    needs = dict(cfg.get("real_comparisons") or {})
    for family, extra in cfg.comparisons.items():
        family = str(family)
        if quick and family in list(cfg.get("quick_skip") or []):
            continue
        if family in needs and str(needs[family]) not in present:
            continue
        overrides = [
            f"comparison={family}",
            f"seed={int(cfg.seed)}",
            *map(str, extra or []),
        ]
        if quick:
            overrides += [str(o) for o in (cfg.quick_overrides.get(family) or [])]
        frames = cfg.cost.quick_max_frames if quick else cfg.cost.max_frames
        overrides.append(f"cost.max_frames={int(frames)}")
        overrides.append(f"data_root={cfg.data_root}")
        plan[family] = compose(config_name="compare", overrides=overrides)
    return plan


def demo_main(cfg: DictConfig) -> Path:
    """Run the whole pipeline; print the index report's path last and return it."""
    from tqdm import tqdm

    start = time.perf_counter()
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
        kind="demo",
        overwrite=bool(cfg.overwrite),
    )
    out.mkdir(parents=True, exist_ok=True)
    plan = _plan(cfg, present)
    datasets: list[dict[str, Any]] = []

    # 1. simulate -------------------------------------------------------------------
    scenes: dict[tuple[str, int, int], Path] = {}
    for ccfg in plan.values():
        comp = ccfg.comparison
        if comp.get("scene") is None:
            continue
        key = (str(comp.scene.name), int(comp.dataset.n_trials), int(comp.dataset.seed))
        scenes.setdefault(key, out / "data" / f"{key[0]}-n{key[1]}-s{key[2]}")
    for (scene_name, n, seed), path in tqdm(
        list(scenes.items()), desc="1/6 simulate", unit="scene", disable=not show
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
    for ccfg in plan.values():
        comp = ccfg.comparison
        if comp.get("scene") is not None:
            key = (
                str(comp.scene.name),
                int(comp.dataset.n_trials),
                int(comp.dataset.seed),
            )
            comp.dataset.path = str(scenes[key])

    # 2. import ---------------------------------------------------------------------------
    if not present:
        print(
            f"real recordings not found under {root} (set SLIPKIT_DATA); skipping the import "
            "stage and the real-data comparison"
        )
    imported: dict[str, Path] = {}
    for source, src_path in tqdm(
        list(present.items()), desc="2/6 import", unit="source", disable=not show
    ):
        t0 = time.perf_counter()
        reader = instantiate(
            compose(
                config_name="import", overrides=[f"source={source}", "path=x", "out=x"]
            ).source
        )
        path = save_dataset(
            reader(src_path), out / "data" / source, overwrite=bool(cfg.overwrite)
        )
        imported[source] = path
        datasets.append(_row(path, "recorded", time.perf_counter() - t0))
    for family, source in (cfg.get("real_comparisons") or {}).items():
        if str(family) in plan and str(source) in imported:
            plan[str(family)].comparison.dataset.path = str(imported[str(source)])

    # 3. train + calibrate + compare ------------------------------------------------------
    from slipkit.compare.commands import run_comparison

    results = {}
    for family, ccfg in tqdm(
        list(plan.items()),
        desc="3/6 train+calibrate+compare",
        unit="family",
        disable=not show,
    ):
        with atomic_dir(
            out / "compare" / family, overwrite=True, kind="comparison"
        ) as tmp:
            results[family] = run_comparison(ccfg, tmp, progress=False)
        results[family].folder = out / "compare" / family
        results[family].report = results[family].folder / "report.md"

    # 4. export the best of each family ------------------------------------------------------
    from slipkit.compare.costs import export_run, time_bundle
    from slipkit.compare.table import choose_deploy, verdict_limits

    best: dict[str, dict[str, Any]] = {}
    exported: dict[str, Path] = {}
    for family, res in tqdm(
        list(results.items()), desc="4/6 export best", unit="family", disable=not show
    ):
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
        if row["export"] != "ok":
            continue
        bundle = out / "exports" / family
        exported[family] = export_run(
            res.folder / "runs" / str(row["estimator"]),
            bundle,
            max_frames=int(cfg.replay.max_frames),
        )

    # 5. replay the test data through the runtime loop -----------------------------------------
    replay: dict[str, Any] = {}
    for family, bundle in tqdm(
        list(exported.items()), desc="5/6 replay", unit="bundle", disable=not show
    ):
        replay[family] = time_bundle(
            bundle, max_frames=int(cfg.replay.max_frames), warmup=int(cfg.replay.warmup)
        )

    # 6. report ---------------------------------------------------------------------------
    with tqdm(total=1, desc="6/6 report", unit="file", disable=not show) as bar:
        report = _write_index(
            out,
            results,
            best,
            exported,
            replay,
            datasets,
            cfg,
            time.perf_counter() - start,
        )
        bar.update(1)
    print("\n" + _table(datasets))
    for family in results:
        b = best.get(family, {})
        r = replay.get(family)
        lat = (
            f"p99 {r.p99_us:.1f} us of {r.budget_p99_us:.4g} us budget"
            if r is not None
            else str(b.get("export", ""))
        )
        note = (
            ""
            if b.get("recommended", True)
            else " (not recommended: no estimator meets the budget)"
        )
        print(f"{family:<18} best {b.get('estimator', '-')!s:<16} {lat}{note}")
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


def _write_index(
    out: Path,
    results: dict[str, Any],
    best: dict[str, dict[str, Any]],
    exported: dict[str, Path],
    replay: dict[str, Any],
    datasets: list[dict[str, Any]],
    cfg: DictConfig,
    seconds: float,
) -> Path:
    lines = [
        "# slipkit demo: which detector to deploy for each sensor",
        "",
        f"Made by `slipkit demo{' quick=true' if cfg.get('quick') else ''}` in {seconds:.0f} s "
        f"(seed {int(cfg.seed)}). Each family's estimators (learned models and analytic "
        "baselines) ran through the same task on the same split; the best was exported to an "
        "ONNX bundle and its held-out test frames replayed through the runtime loop "
        "(onnxruntime, 1 thread, batch 1) against the sensor's budget.",
        "",
        "| family | deploy | kind | primary metric | delay (ms) | replay p50 (us) | replay p99 (us) | p99 budget (us) | within budget | bundle | report |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for family, res in results.items():
        b = best.get(family, {})
        r = replay.get(family)
        primary = str(res.table.attrs.get("primary", ""))
        bundle = (
            f"[exports/{family}](exports/{family})"
            if family in exported
            else str(b.get("export", ""))
        )
        lines.append(
            "| "
            + " | ".join(
                [
                    family,
                    f"`{b.get('estimator', '-')}`"
                    + (
                        ""
                        if b.get("recommended", True)
                        else " (not recommended: no estimator meets the budget)"
                    ),
                    str(b.get("kind", "")),
                    f"{primary} {_fmt(b.get(primary), '{:.4g}')}"
                    if primary
                    else _fmt(b.get("score"), "{:.4g}"),
                    _fmt(b.get("delay_ms"), "{:.1f}"),
                    _fmt(None if r is None else r.p50_us, "{:.1f}"),
                    _fmt(None if r is None else r.p99_us, "{:.1f}"),
                    _fmt(None if r is None else r.budget_p99_us, "{:.4g}"),
                    ""
                    if r is None or r.within_budget is None
                    else ("yes" if r.within_budget else "no"),
                    bundle,
                    f"[compare/{family}/report.md](compare/{family}/report.md)",
                ]
            )
            + " |"
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
    path = out / "report.md"
    atomic_write_text(path, "\n".join(lines))
    return path


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
