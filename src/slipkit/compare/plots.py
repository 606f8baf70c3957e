"""The comparison's figures (matplotlib, Agg backend): one PNG per question the report asks."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.ticker as mticker
import numpy as np
import pandas as pd

from slipkit.compare.adapters import Evaluation
from slipkit.compare.table import DEFAULT_LIMITS, _rejection, metric_unit, score_of

COLORS = {"learned": "tab:blue", "analytic": "tab:orange"}


def _save(fig: Any, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


#: point-label offsets (points) cycled over the points in x order, so neighbours alternate
#: above / below and left / right; a hand-written stagger (no adjustText dependency)
LABEL_OFFSETS = ((6, 5), (6, -11), (-6, 5), (-6, -11))


def seeds_text(df: pd.DataFrame, n_seeds: int | None = None) -> str:
    """``3 seeds, mean`` / ``1 seed``: how many seeds a table's rows are over
    (``n_seeds`` given, else the table's ``n_seeds`` column, else one)."""
    if n_seeds is None:
        values = pd.to_numeric(
            df["n_seeds"] if "n_seeds" in df else pd.Series(dtype=float),
            errors="coerce",
        ).dropna()
        n_seeds = int(values.max()) if len(values) else 1
    return f"{n_seeds} seeds, mean" if n_seeds > 1 else "1 seed"


def pareto_points(
    df: pd.DataFrame, limits: Mapping[str, float | None] | None = None
) -> pd.DataFrame:
    """What :func:`plot_pareto` draws: one row per estimator with a measured p99 and a score.

    ``limits``: the comparison's verdict limits (:func:`slipkit.compare.table.verdict_limits`;
    None: the defaults) deciding which rows the verdict passes over.

    Returns
    -------
    pandas.DataFrame
        ``estimator``, ``kind``, ``x_us`` (p99 compute per frame, us: the percentile the
        budget is checked on), ``score``, ``pareto`` (bool), ``budget_us`` (the p99
        budget), ``passed_over`` (why the verdict cannot recommend it; "" when it can),
        ``dx``, ``dy`` (label offset, points, staggered between neighbours).
    """
    x = df["p99_us"].to_numpy(float)
    y = df["score"].to_numpy(float)
    ok = df[np.isfinite(x) & np.isfinite(y)]
    chosen = dict(DEFAULT_LIMITS if limits is None else limits)
    why = [
        _rejection(
            r,
            max_alarms_per_disturbance=chosen.get("max_alarms_per_disturbance"),
            max_early_alarm_rate=chosen.get("max_early_alarm_rate"),
        )
        or ""
        for _, r in ok.iterrows()
    ]
    pts = pd.DataFrame(
        {
            "estimator": ok["estimator"].astype(str).to_numpy(),
            "kind": ok["kind"].astype(str).to_numpy(),
            "x_us": ok["p99_us"].to_numpy(float),
            "score": ok["score"].to_numpy(float),
            "pareto": ok["pareto"].astype(bool).to_numpy(),
            "budget_us": ok["budget_p99_us"].to_numpy(float),
            "passed_over": why,
        }
    )
    order = np.lexsort((pts["score"].to_numpy(), pts["x_us"].to_numpy()))
    offsets = np.zeros((len(pts), 2))
    for rank, i in enumerate(order):
        offsets[i] = LABEL_OFFSETS[rank % len(LABEL_OFFSETS)]
    pts["dx"] = offsets[:, 0]
    pts["dy"] = offsets[:, 1]
    return pts


def score_label(primary: str, columns: Sequence[str] = ()) -> str:
    """The score axis label with its unit: ``-rmse (N), higher is better`` or ``accuracy (fraction)``."""
    unit = metric_unit(primary, columns)
    if score_of({primary: 1.0}, primary) < 0:
        return f"score = -{primary} ({unit or 'its unit'}), higher is better"
    return f"{primary} ({unit or 'fraction, 0-1'})"


def pareto_figure(
    df: pd.DataFrame,
    primary: str,
    title: str,
    *,
    limits: Mapping[str, float | None] | None = None,
    n_seeds: int | None = None,
) -> Any | None:
    """The Pareto figure (score against p99 compute per frame), or None with nothing to draw.

    Estimators the verdict passes over (over budget, a limit, not exported) are hollow
    grey markers with their own legend entry; the title says how many seeds."""
    pts = pareto_points(df, limits)
    if pts.empty:
        return None
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ok = pts[pts["passed_over"] == ""]
    for kind in sorted(set(ok["kind"])):  # legend entries only for kinds drawn
        part = ok[ok["kind"] == kind]
        ax.scatter(
            part["x_us"],
            part["score"],
            c=COLORS.get(kind, "tab:gray"),
            s=40,
            label=kind,
            zorder=3,
        )
    out = pts[pts["passed_over"] != ""]
    if len(out):
        ax.scatter(
            out["x_us"],
            out["score"],
            s=40,
            facecolors="none",
            edgecolors="0.5",
            linewidths=1.3,
            label="passed over by the verdict",
            zorder=3,
        )
    for _, r in pts.iterrows():
        ax.annotate(
            r["estimator"],
            (r["x_us"], r["score"]),
            textcoords="offset points",
            xytext=(r["dx"], r["dy"]),
            ha="left" if r["dx"] >= 0 else "right",
            fontsize=8,
        )
    front = pts[pts["pareto"]].sort_values("x_us")
    if len(front):
        ax.step(
            front["x_us"],
            front["score"],
            where="post",
            color="k",
            lw=1.2,
            label="Pareto front",
            zorder=2,
        )
        ax.scatter(
            front["x_us"],
            front["score"],
            s=140,
            facecolors="none",
            edgecolors="k",
            zorder=4,
        )
    budgets = sorted(set(pts["budget_us"].dropna().round(3)))
    for i, b in enumerate(budgets):
        ax.axvline(
            b,
            color="tab:red",
            ls="--",
            lw=1,
            label="p99 budget" if i == 0 else None,
        )
        ax.text(
            b,
            ax.get_ylim()[0],
            f" p99 budget {b:.4g} us",
            color="tab:red",
            fontsize=8,
            rotation=90,
            va="bottom",
            ha="right",
        )
    ax.set_xscale("log")
    # plain numbers at 1, 2, 5 x 10^k only: the default minor labels (3x10^1, 4x10^1) collide
    ax.xaxis.set_major_locator(mticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(mticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(mticker.NullFormatter())
    ax.margins(x=0.12, y=0.12)  # room for the staggered labels of the edge points
    ax.set_xlabel("compute per frame, p99 (us, ONNX runtime loop, 1 thread)")
    ax.set_ylabel(score_label(primary, list(df.columns)))
    ax.set_title(f"{title} ({seeds_text(df, n_seeds)})", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="best")
    return fig


def plot_pareto(
    df: pd.DataFrame,
    primary: str,
    title: str,
    path: Path,
    *,
    limits: Mapping[str, float | None] | None = None,
    n_seeds: int | None = None,
) -> Path | None:
    """Score against p99 compute per frame (us, log), the Pareto front joined, p99 budget
    lines, passed-over estimators hollow grey (:func:`pareto_figure`)."""
    fig = pareto_figure(df, primary, title, limits=limits, n_seeds=n_seeds)
    return None if fig is None else _save(fig, path)


def _seed_title(seed: int | None) -> str:
    """Which seed a per-seed figure shows (the comparison plots its first seed's runs)."""
    return "first seed's run" if seed is None else f"seed {seed}"


def plot_curves(
    evals: Mapping[str, Evaluation], which: str, path: Path, *, seed: int | None = None
) -> Path | None:
    """Accuracy against time from onset (``vs_time``) or against window length (``vs_width``)."""
    curves = {
        k: getattr(e, which) for k, e in evals.items() if getattr(e, which) is not None
    }
    if not curves:
        return None
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    xcol, xlabel = (
        ("t_rel_s", "window end relative to slip onset (s)")
        if which == "vs_time"
        else ("ms", "window length (ms)")
    )
    for name, c in curves.items():
        ax.plot(
            c[xcol],
            c["accuracy"],
            marker="o" if which == "vs_width" else None,
            ms=4,
            label=name,
        )
    if which == "vs_time":
        ax.axvline(0.0, color="k", lw=0.8, ls=":")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("test accuracy (fraction, 0-1)")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"test accuracy ({_seed_title(seed)})", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def plot_roc(
    evals: Mapping[str, Evaluation], path: Path, *, seed: int | None = None
) -> Path | None:
    """ROC curves on the test side, each estimator's chosen operating point marked."""
    rocs = {k: e.roc for k, e in evals.items() if e.roc is not None}
    if not rocs:
        return None
    fig, ax = plt.subplots(figsize=(5.0, 4.6))
    for name, r in rocs.items():
        (line,) = ax.plot(
            r["fpr"],
            r["tpr"],
            lw=1.3,
            label=f"{name} (AUC {r['auc']:.3f}, per {r['unit']})",
        )
        pt = r.get("point")
        if pt is not None and all(math.isfinite(v) for v in pt):
            ax.plot(*pt, "o", color=line.get_color(), ms=7, mec="k")
    ax.plot([0, 1], [0, 1], color="0.6", lw=0.8, ls=":")
    ax.set_xlabel("false positive rate (fraction, 0-1)")
    ax.set_ylabel("true positive rate (fraction, 0-1)")
    ax.set_title(f"ROC, {_seed_title(seed)} (dots: the chosen threshold)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    return _save(fig, path)


def plot_delays(
    evals: Mapping[str, Evaluation], path: Path, *, seed: int | None = None
) -> Path | None:
    """Detection delay from the true onset (ms) of every detected test slip, per estimator."""
    data = {k: e.delays_ms for k, e in evals.items() if e.delays_ms}
    if not data:
        return None
    fig, ax = plt.subplots(figsize=(6.4, 0.6 + 0.55 * len(data) + 1.2))
    names = list(data)
    ax.boxplot(
        [data[n] for n in names],
        orientation="horizontal",
        tick_labels=names,
        showfliers=False,
    )
    rng = np.random.default_rng(0)  # jitter only; fixed so the figure is reproducible
    for i, n in enumerate(names, start=1):
        v = np.asarray(data[n])
        ax.scatter(v, i + rng.uniform(-0.15, 0.15, len(v)), s=10, alpha=0.6)
    ax.axvline(0.0, color="k", lw=0.8, ls=":")
    ax.set_xlabel("detection delay after the true slip onset (ms)")
    ax.set_ylabel("estimator")
    ax.set_title(f"detected test slips ({_seed_title(seed)})", fontsize=10)
    ax.grid(alpha=0.3, axis="x")
    return _save(fig, path)


def plot_latency(costs: Mapping[str, Any], path: Path) -> Path | None:
    """Per-decision latency histograms (us) of the exported estimators on one shared x axis.

    The dashed red line is the p99 budget and the dotted black line the p99 it is
    checked on (:func:`slipkit.compare.table.block_p99`: the median of 5 block p99s).
    The x axis ends at 1.5 x the largest p99 or budget; slower decisions (stalls) are
    counted into the last bin and their number given in the panel's title.
    """
    data = {k: c for k, c in costs.items() if c.exported and len(c.latency_us)}
    if not data:
        return None
    hi = 1.5 * max(
        max(float(c.p99_us) for c in data.values()),
        max(float(c.budget_p99_us) for c in data.values()),
    )
    fig, axes = plt.subplots(
        len(data), 1, figsize=(6.4, 1.2 + 1.5 * len(data)), squeeze=False, sharex=True
    )
    for ax, (name, c) in zip(axes[:, 0], data.items(), strict=True):
        lat = np.asarray(c.latency_us, dtype=float)
        over = int((lat > hi).sum())
        ax.hist(
            np.clip(lat, 0, hi), bins=60, range=(0, hi), color="tab:blue", alpha=0.8
        )
        ax.axvline(
            c.budget_p99_us,
            color="tab:red",
            ls="--",
            lw=1.2,
            label=f"p99 budget {c.budget_p99_us:.4g} us",
        )
        ax.axvline(
            c.p99_us,
            color="k",
            ls=":",
            lw=1.2,
            label=f"p99 {c.p99_us:.1f} us (checked)",
        )
        title = f"{name}: p50 {c.p50_us:.1f} us, {len(lat)} decisions"
        if over:
            title += f", {over} above {hi:.0f} us (last bin)"
        ax.set_title(title, fontsize=9)
        ax.set_ylabel("decisions (count)", fontsize=8)
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlim(0, hi)
    axes[-1, 0].set_xlabel("frame arrival -> decision (us)")
    return _save(fig, path)


def plot_search(evals: Mapping[str, Evaluation], path: Path) -> Path | None:
    """Best cross-validated score so far against the number of in-run search trials."""
    data = {k: e.search for k, e in evals.items() if e.search is not None}
    if not data:
        return None
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    for name, h in data.items():
        v = h["value"].to_numpy(float)
        ax.plot(h["number"] + 1, v, "o", ms=3, alpha=0.5)
        ax.plot(h["number"] + 1, np.fmax.accumulate(v), label=f"{name} (best so far)")
    ax.set_xlabel("search trials (count, Optuna TPE)")
    ax.set_ylabel("cross-validated objective (its unit; training side)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def plot_confusions(
    evals: Mapping[str, Evaluation], path: Path, *, seed: int | None = None
) -> Path | None:
    """Test confusion matrices (rows: true class, columns: predicted), one panel per estimator."""
    data = {k: e.confusion for k, e in evals.items() if e.confusion is not None}
    if not data:
        return None
    n = len(data)
    fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.2), squeeze=False)
    for ax, (name, (labels, cm)) in zip(axes[0], data.items(), strict=True):
        cm = np.asarray(cm, dtype=float)
        norm = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)
        ax.imshow(norm, cmap="Blues", vmin=0, vmax=1)
        for i in range(cm.shape[0]):
            for j in range(cm.shape[1]):
                ax.text(
                    j,
                    i,
                    f"{int(cm[i, j])}",
                    ha="center",
                    va="center",
                    fontsize=8,
                    color="white" if norm[i, j] > 0.5 else "black",
                )
        ax.set_xticks(
            range(len(labels)),
            labels,
            rotation=45,
            ha="right",
            rotation_mode="anchor",
            fontsize=7,
        )
        ax.set_yticks(range(len(labels)), labels, fontsize=7)
        ax.set_title(f"{name} (counts)", fontsize=9)
        ax.set_xlabel("predicted class", fontsize=8)
    axes[0, 0].set_ylabel("true class", fontsize=8)
    fig.suptitle(f"test confusion ({_seed_title(seed)})", fontsize=10)
    return _save(fig, path)


__all__ = [
    "pareto_figure",
    "pareto_points",
    "plot_confusions",
    "plot_curves",
    "plot_delays",
    "plot_latency",
    "plot_pareto",
    "plot_roc",
    "plot_search",
    "score_label",
    "seeds_text",
]
