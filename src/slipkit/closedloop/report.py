"""The closed-loop table (mean +- std over seeds), the per-speed table, the headline plot, report.md."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf

#: Per-seed outcome columns: name -> (how it is computed from a seed's trials, unit).
OUTCOMES = {
    "caught_pct": "objects caught (not dropped), % of trials",
    "dropped_pct": "objects dropped, % of trials",
    "slip_mm": "slip distance at arrest, mm (caught objects whose slip was detected at or after its onset; "
    "FSR, BioTac: all slides of the trial)",
    "onset_to_arrest_ms": "slip onset to arrest, ms (the same objects)",
    "delay_ms": "detection delay in the loop, ms (declared at or after the onset)",
    "false_alarm_pct": "declared while the object was not slipping (TacTip: before it slipped), % of trials",
    "extra_force_N": "peak grip force a false alarm added (TacTip: above the open-loop retraction's; "
    "FSR, BioTac: above the same controller told only the true declarations), N (mean over trials)",
    "extra_impulse_Ns": "integral of that extra force, N s (mean over trials)",
}


def _nanmean(series: pd.Series) -> float:
    x = series.to_numpy(dtype=float)
    x = x[np.isfinite(x)]
    return float(x.mean()) if len(x) else math.nan


def per_seed(results: pd.DataFrame) -> pd.DataFrame:
    """One row per (detector, seed) with the :data:`OUTCOMES` columns."""
    rows = []
    for (det, seed), g in results.groupby(["detector", "seed"], sort=False):
        # Slip of a *detected* slip (declared at or after the onset): a declaration
        # before the onset is a false alarm, even when the latency lets the object
        # slip a little anyway (those rows stay in results.csv).
        caught_slip = g[g["delay_ms"].notna() & ~g["dropped"]]
        rows.append(
            {
                "detector": det,
                "seed": seed,
                "caught_pct": 100.0 * float((~g["dropped"]).mean()),
                "dropped_pct": 100.0 * float(g["dropped"].mean()),
                "slip_mm": _nanmean(caught_slip["slip_mm"]),
                "onset_to_arrest_ms": _nanmean(caught_slip["onset_to_arrest_ms"]),
                "delay_ms": _nanmean(g["delay_ms"]),
                "false_alarm_pct": 100.0 * float(g["false_alarm"].mean()),
                "extra_force_N": float(g["extra_force_N"].mean()),
                "extra_impulse_Ns": float(g["extra_impulse_Ns"].mean()),
            }
        )
    return pd.DataFrame(rows)


def summarize(
    results: pd.DataFrame,
    info: Mapping[str, Mapping[str, Any]],
    latencies: Mapping[str, np.ndarray],
) -> pd.DataFrame:
    """One row per detector: each outcome's mean and std over seeds, accuracy and compute.

    ``<outcome>`` is the mean over seeds of the per-seed value, ``<outcome>_std`` its
    standard deviation (``ddof=1``; NaN with one seed). ``p50_us`` / ``p99_us`` are
    percentiles of every decision's latency through the runtime loop (frame arrival
    -> decision), pooled over all trials.
    """
    seeds = per_seed(results)
    rows = []
    for det, g in seeds.groupby("detector", sort=False):
        row: dict[str, Any] = {"detector": det}
        meta = dict(info.get(str(det), {}))
        row["kind"] = meta.get("kind", "")
        row["debounce_k"] = meta.get("debounce_k", math.nan)
        for key in OUTCOMES:
            values = g[key].to_numpy(dtype=float)
            finite = values[np.isfinite(values)]
            row[key] = float(finite.mean()) if len(finite) else math.nan
            row[f"{key}_std"] = (
                float(finite.std(ddof=1)) if len(finite) > 1 else math.nan
            )
        row["accuracy_pct"] = meta.get("accuracy_pct", math.nan)
        row["balanced_accuracy_pct"] = meta.get("balanced_accuracy_pct", math.nan)
        lat = np.asarray(latencies.get(str(det), np.zeros(0)), dtype=float)
        p50, p99 = np.percentile(lat, [50, 99]) if len(lat) else (math.nan, math.nan)
        row["p50_us"], row["p99_us"] = float(p50), float(p99)
        row["p99_budget_us"] = meta.get("p99_budget_us", math.nan)
        row["n_decisions"] = len(lat)
        row["n_trials"] = int((results["detector"] == det).sum())
        rows.append(row)
    return pd.DataFrame(rows)


def per_condition(
    results: pd.DataFrame, detectors: Sequence[str], label: str = "speed (mm/s)"
) -> pd.DataFrame:
    """Caught % and mean slip at arrest (mm, caught objects) per condition, for ``detectors``.

    ``label`` heads the condition column (the scenario's ``condition_label``).
    """
    rows = []
    for value, g in results.groupby("condition"):
        row: dict[str, Any] = {label: f"{value:g}"}
        for det in detectors:
            d = g[g["detector"] == det]
            if d.empty:
                continue
            caught = d[~d["dropped"] & d["delay_ms"].notna()]
            row[f"{det} caught %"] = 100.0 * float((~d["dropped"]).mean())
            row[f"{det} slip mm"] = _nanmean(caught["slip_mm"])
        rows.append(row)
    return pd.DataFrame(rows)


def _pm(mean: float, std: float, digits: int) -> str:
    if not math.isfinite(mean):
        return "-"
    if not math.isfinite(std):
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} +- {std:.{digits}f}"


def _num(value: Any, digits: int) -> str:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return "-"
    return f"{v:.{digits}f}" if math.isfinite(v) else "-"


def markdown_table(summary: pd.DataFrame) -> str:
    """The headline table in Markdown (mean +- std over seeds)."""
    head = (
        "| detector | k | caught % | slip at arrest (mm) | onset -> arrest (ms) | "
        "delay (ms) | false alarms % | extra grip (N) | extra grip (N s) | "
        "frame accuracy % | p50 (us) | p99 (us) |"
    )
    lines = [head, "|" + "---|" * 12]
    for _, r in summary.iterrows():
        lines.append(
            "| "
            + " | ".join(
                [
                    str(r["detector"]),
                    _num(r["debounce_k"], 0),
                    _pm(r["caught_pct"], r["caught_pct_std"], 1),
                    _pm(r["slip_mm"], r["slip_mm_std"], 1),
                    _pm(r["onset_to_arrest_ms"], r["onset_to_arrest_ms_std"], 0),
                    _pm(r["delay_ms"], r["delay_ms_std"], 1),
                    _pm(r["false_alarm_pct"], r["false_alarm_pct_std"], 1),
                    _pm(r["extra_force_N"], r["extra_force_N_std"], 3),
                    _pm(r["extra_impulse_Ns"], r["extra_impulse_Ns_std"], 4),
                    _num(r["accuracy_pct"], 2),
                    _num(r["p50_us"], 0),
                    _num(r["p99_us"], 0),
                ]
            )
            + " |"
        )
    return "\n".join(lines)


#: a detector's debounce variants are named ``<base>_k<k>`` (``svm_k1`` .. ``svm_k4``)
_DEBOUNCE_SUFFIX = re.compile(r"_k\d+$")


def debounce_groups(summary: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The bundle detectors grouped by the run their debounce variants share (the name
    without its ``_k<k>`` suffix), each group's rows in debounce order: one curve per
    detector over its debounce where the scenario has several, else one point."""
    bundles = summary[summary["kind"] == "bundle"]
    if bundles.empty:
        return {}
    base = bundles["detector"].astype(str).str.replace(_DEBOUNCE_SUFFIX, "", regex=True)
    return {
        str(name): g.sort_values("debounce_k")
        for name, g in bundles.groupby(base, sort=False)
    }


def headline_plot(summary: pd.DataFrame, path: Path, *, title: str) -> Path:
    """Slip at arrest against detection delay, false alarms against delay, and slip
    against compute per frame (p99).

    Left: every detector with a finite delay (bundles, oracle, delayed oracles; the
    delayed oracles as the plant's own curve), a detector's debounce variants joined in
    debounce order (:func:`debounce_groups`). Middle: the bundles' false-alarm rate
    against their delay, joined the same way. Right: the bundles only (the bounds
    compute nothing), against the p99 of their per-frame latency, with the p99 budget as
    a vertical line. Error bars: std over seeds.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax3, ax2) = plt.subplots(
        1, 3, figsize=(18, 4.4), constrained_layout=True
    )
    curve = summary[summary["kind"] == "delayed oracle"]
    base = summary[summary["kind"] == "oracle"]
    plant = pd.concat([base, curve]).sort_values("delay_ms")
    if len(plant) > 1:
        ax1.plot(
            plant["delay_ms"],
            plant["slip_mm"],
            "-",
            color="0.6",
            label="plant: oracle + fixed delay",
        )
    markers = "osD^vP*Xh"
    bundles = summary[summary["kind"] == "bundle"]
    for i, (group, g) in enumerate(debounce_groups(summary).items()):
        m = markers[i % len(markers)]
        several = len(g) > 1
        label = f"{group} (k {', '.join(_num(k, 0) for k in g['debounce_k'])})"
        for ax, y in ((ax1, "slip_mm"), (ax3, "false_alarm_pct")):
            bars = ax.errorbar(
                g["delay_ms"],
                g[y],
                xerr=np.nan_to_num(g["delay_ms_std"].to_numpy(float)),
                yerr=np.nan_to_num(g[f"{y}_std"].to_numpy(float)),
                fmt=f"{m}-" if several else m,
                capsize=3,
                label=label if several else str(g["detector"].iloc[0]),
            )
            if several:  # name each point's debounce beside it
                for _, r in g.iterrows():
                    ax.annotate(
                        f"k={_num(r['debounce_k'], 0)}",
                        (r["delay_ms"], r[y]),
                        textcoords="offset points",
                        xytext=(4, 4),
                        fontsize=7,
                        color=bars[0].get_color(),
                    )
        ax2.errorbar(
            g["p99_us"],
            g["slip_mm"],
            yerr=np.nan_to_num(g["slip_mm_std"].to_numpy(float)),
            fmt=m,
            capsize=3,
            label=label if several else str(g["detector"].iloc[0]),
        )
    for _, r in base.iterrows():
        ax1.errorbar(
            r["delay_ms"],
            r["slip_mm"],
            yerr=np.nan_to_num(r["slip_mm_std"]),
            fmt="k*",
            markersize=10,
            capsize=3,
            label=f"oracle ({_num(r['delay_ms'], 1)} ms)",
        )
    ax1.set_xlabel("detection delay in the loop (ms)")
    ax1.set_ylabel("slip distance at arrest (mm)")
    ax1.set_title("slip against detection delay")
    # Outside the axes: no legend can cover a point, whatever the numbers.
    ax1.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax3.set_xlabel("detection delay in the loop (ms)")
    ax3.set_ylabel("false alarms (% of trials)")
    ax3.set_title("false alarms against detection delay")
    for ax in (ax1, ax3):
        ax.margins(x=0.08, y=0.1)  # room for the k= labels of the edge points
    budgets = bundles["p99_budget_us"].dropna().unique()
    styles = ["--", ":", "-.", (0, (5, 1))]
    for i, b in enumerate(budgets):
        label = f"p99 budget {b:.0f} us"
        if len(budgets) > 1:  # several sensor streams: say whose budget each line is
            names = bundles.loc[bundles["p99_budget_us"] == b, "detector"]
            label += f" ({', '.join(map(str, names))})"
        ax2.axvline(float(b), color="r", linestyle=styles[i % len(styles)], label=label)
    if len(bundles):
        from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

        ax2.set_xscale("log")
        # Major ticks only at 1-2-5 decades, labelled plainly; unlabelled minor ticks
        # (labelled ones overlap on a span of less than a decade).
        ax2.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax2.xaxis.set_major_formatter(ScalarFormatter())
        ax2.xaxis.set_minor_formatter(NullFormatter())
        ax2.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax2.set_xlabel("compute per frame, p99 of the runtime loop (us)")
    ax2.set_ylabel("slip distance at arrest (mm)")
    ax2.set_title("slip against compute per frame")
    fig.suptitle(title)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(
    folder: Path,
    *,
    scenario: DictConfig,
    results: pd.DataFrame,
    summary: pd.DataFrame,
    timings: Mapping[str, Any],
    command: str,
    seeds: Sequence[int],
) -> Path:
    """``report.md`` and ``closedloop_<name>.png`` in ``folder``."""
    name = str(scenario.name)
    png = headline_plot(
        summary,
        folder / f"closedloop_{name}.png",
        title=f"{name}: closed-loop slip ({len(seeds)} seed{'s' if len(seeds) > 1 else ''}, "
        "mean +- std over seeds)",
    )
    bundles = [str(d) for d in summary.loc[summary["kind"] == "bundle", "detector"]]
    label = str(timings.get("condition_label", "condition"))
    speeds = per_condition(results, [*bundles, "oracle"], label)
    plant = OmegaConf.to_container(scenario.plant, resolve=True)
    loop = timings.get("loop_s", {})
    lines = [
        f"# Closed loop: {name}",
        "",
        f"Command: `{command}`",
        "",
        f"Scene `{scenario.scene}`; plant {plant}; {label} "
        f"{', '.join(f'{s:g}' for s in timings.get('conditions', []))}; "
        f"{int(scenario.trials_per_speed)} trials per condition and seed; seeds {list(seeds)}.",
        "",
        "Mean +- std over seeds (each seed's value is the mean over its trials).",
        "",
        markdown_table(summary),
        "",
        f"![slip against delay and compute]({png.name})",
        "",
        f"## Per {label.split(' (')[0]} (all seeds pooled)",
        "",
        # The condition column as given (0.02 s must not print as 0.0), the rest to 0.1.
        speeds.to_markdown(
            index=False, floatfmt=["g"] + [".1f"] * (len(speeds.columns) - 1)
        ),
        "",
        "## Columns",
        "",
        *[f"- `{k}`: {v}" for k, v in OUTCOMES.items()],
        "- frame accuracy: the run's held-out frames correct (offline, `metrics.json`); "
        "p50 / p99: every decision's latency through `StreamLoop` (frame arrival -> decision), "
        "one onnxruntime thread.",
        "",
        "## Cost of this run",
        "",
        f"- train + export + load: {timings.get('prepare_s', math.nan):.1f} s",
        *[f"- loop `{d}`: {s:.2f} s" for d, s in loop.items()],
        f"- total: {timings.get('total_s', math.nan):.1f} s",
        "",
    ]
    path = folder / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path
