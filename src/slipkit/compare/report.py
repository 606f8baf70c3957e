"""``report.md``: the comparison's tables, plots, verdict, exact command and resolved config."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from slipkit.compare.table import (
    BORDERLINE,
    DeployChoice,
    choose_deploy,
    disturbance_rate,
    is_borderline,
    metric_unit,
    per_unit,
    score_of,
)
from slipkit.evaluate.events import Cost
from slipkit.runtime.budget import RULE_TEXT, judge_p99

#: (column, header, format) of the report's main table
MAIN = (
    ("estimator", "estimator", "{}"),
    ("kind", "kind", "{}"),
    ("accuracy", "acc", "{:.3f}"),
    ("balanced_accuracy", "bal. acc", "{:.3f}"),
    ("f1", "F1", "{:.3f}"),
    ("tpr", "TPR", "{:.3f}"),
    ("tnr", "TNR", "{:.3f}"),
    ("roc_auc", "ROC AUC", "{:.3f}"),
    ("rmse", "RMSE", "{:.3g}"),
    ("smse", "SMSE", "{:.3g}"),
    ("event_tpr", "event TPR", "{:.3f}"),
    ("event_tnr", "event TNR", "{:.3f}"),
    ("event_auc", "event AUC", "{:.3f}"),
    # trial events at the deployed operating point (slipkit.evaluate.events)
    ("cost", "cost (per trial)", "{:.3f}"),
    ("detected_rate", "slips detected", "{:.2f}"),
    ("early_alarm_rate", "early alarms (trials)", "{:.2f}"),
    ("delay_p90_ms", "delay (ms, p90)", "{:.1f}"),
    ("threshold", "threshold", "{:.4g}"),
    ("debounce_k", "debounce k", "{:.0f}"),
    # TacTip trial events (adapters.trial_events): first alarm within 2 frames of onset
    ("on_time_rate", "on time (<= 2 frames)", "{:.3f}"),
    ("no_early_alarm_rate", "no early alarm", "{:.3f}"),
    ("late_slips", "late", "{:.0f}"),
    ("delay_ms", "delay (ms, median)", "{:.1f}"),
    ("missed", "missed", "{:.0f}"),
    ("false_alarms_per_min", "false alarms / min", "{:.2f}"),
    ("disturbances", "disturbances", "{:.0f}"),
    ("alarms_per_disturbance", "alarms / disturbance", "{:.2f}"),
)
#: the window tasks' controls beside the headline (columns from adapters._window_controls)
CONTROLS = (
    ("estimator", "estimator", "{}"),
    ("accuracy", "window acc", "{:.3f}"),
    ("balanced_accuracy", "window bal.", "{:.3f}"),
    ("sequence_accuracy", "sequence acc", "{:.3f}"),
    ("sequence_balanced_accuracy", "sequence bal.", "{:.3f}"),
    ("first_frame_accuracy", "first frame only", "{:.3f}"),
    ("dynamics_accuracy", "dynamics only", "{:.3f}"),
    ("dynamics_balanced_accuracy", "dynamics bal.", "{:.3f}"),
    ("majority_accuracy", "majority class", "{:.3f}"),
)
COST = (
    ("estimator", "estimator", "{}"),
    ("fit_s", "fit (s, all fits)", "{:.3g}"),
    ("fit_calls", "fits", "{:.0f}"),
    ("window_frames", "window (frames)", "{:.0f}"),
    ("window_ms", "window (ms)", "{:.3g}"),
    ("decision_frames", "frames to a decision", "{:.0f}"),
    ("p50_us", "p50 (us)", "{:.1f}"),
    ("p99_us", "p99 (us)", "{:.1f}"),
    ("p99_quiet_us", "p99, quietest block (us)", "{:.1f}"),
    ("p99_unpaced_us", "p99 back to back (us)", "{:.1f}"),
    ("budget_p99_us", "p99 budget (us)", "{:.4g}"),
    ("within_budget", "within budget", "{}"),
    ("pareto", "Pareto", "{}"),
    ("export", "deployment", "{}"),
)


def fmt(value: Any, spec: str) -> str:
    """One table cell: blank for missing values."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, bool) or spec == "{}":
        return (
            {True: "yes", False: "no"}.get(value, str(value))
            if isinstance(value, bool)
            else str(value)
        )
    try:
        return spec.format(float(value))
    except (TypeError, ValueError):
        return str(value)


def markdown_table(df: pd.DataFrame, spec: Sequence[tuple[str, str, str]]) -> str:
    """``df`` as a Markdown table of the columns in ``spec`` that hold any value."""
    cols = [
        (c, h, f)
        for c, h, f in spec
        if c in df
        and (c == "estimator" or df[c].map(lambda v: fmt(v, "{}") != "").any())
    ]
    lines = [
        "| " + " | ".join(h for _, h, _ in cols) + " |",
        "|" + "|".join("---" for _ in cols) + "|",
    ]
    for _, r in df.iterrows():
        lines.append("| " + " | ".join(cell(r, c, f) for c, _, f in cols) + " |")
    return "\n".join(lines)


#: columns fixed by the config or the data layout (a spread over seeds says nothing there),
#: and the latencies: with several seeds they are percentiles of all seeds' decisions
#: pooled, not means over seeds (each seed's are in seeds.csv)
NO_SPREAD = frozenset(
    {
        "p50_us",
        "p99_us",
        "p99_quiet_us",
        "p99_unpaced_us",
        "budget_p99_us",
        "frame_period_us",
        "fit_calls",
        "window_frames",
        "window_ms",
        "decision_frames",
        "disturbances",
        "n_slips",
        "event_trials",
    }
)


def cell(row: pd.Series, column: str, spec: str) -> str:
    """``row[column]`` formatted, as ``mean ± std`` when the row has a finite ``<column>_std``
    (a comparison over several seeds)."""
    text = fmt(row[column], spec)
    std = row.get(f"{column}_std")
    if (
        text
        and spec != "{}"
        and column not in NO_SPREAD
        and isinstance(std, float)
        and math.isfinite(std)
    ):
        text += f" ± {fmt(std, spec)}"
    return text


def margin_text(p99_us: float, budget_us: float, margin: float) -> str:
    """``p99 87.2 us = 0.10 x the 833.3 us budget``, flagged when borderline (noisy)."""
    text = f"p99 {p99_us:.1f} us = {margin:.2f} x the {budget_us:.4g} us budget"
    if is_borderline(margin):
        text += (
            f" (borderline: between {BORDERLINE:.2f} and {1 / BORDERLINE:.2f} x the budget, "
            "a re-measure on a busy machine may land on the other side)"
        )
    return text


def deploy_lines(
    df: pd.DataFrame,
    primary: str,
    *,
    max_alarms_per_disturbance: float | None = None,
    max_early_alarm_rate: float | None = None,
    cost: Cost | None = None,
) -> list[str]:
    """The deploy decision of :func:`~slipkit.compare.table.choose_deploy` as Markdown lines.

    The limits (a comparison's ``verdict:``) are passed on to the rule and printed
    beside the chosen row's own rates; with ``cost`` (a detection comparison) the
    cost's weights and which trials chose the operating points are stated.

    The recommended estimator with its p99 / budget margin, or "no estimator meets the
    budget" and the best-scoring one with its p99; a tie within the spread over seeds
    and what broke it; then each higher-scoring estimator passed over with its reason.
    """
    limit = max_alarms_per_disturbance
    choice = choose_deploy(
        df,
        max_alarms_per_disturbance=limit,
        max_early_alarm_rate=max_early_alarm_rate,
    )
    best = choice.row
    if best is None:
        return ["No estimator produced a score."]
    p99 = float(best["p99_us"])
    cost_text = (
        ", " + margin_text(p99, float(best["budget_p99_us"]), choice.margin)
        if math.isfinite(choice.margin)
        else f" ({best['export']})"
    )
    delay = (
        (
            f", median detection delay {best['delay_ms']:.1f} ms"
            if math.isfinite(float(best["delay_ms"]))
            else ""
        )
        + _event_note(best, max_early_alarm_rate)
        + _disturbance_note(best, limit)
    )
    what = (
        f"`{best['estimator']}` ({best['kind']}, {best['class']}): {primary} "
        f"{cell(best, primary, '{:.4g}')}{_over_seeds(best)}{cost_text}{delay}."
    )
    limits = [
        name
        for name, value in (
            ("the early-alarm limit", max_early_alarm_rate),
            ("the disturbance limit", limit),
        )
        if value is not None and _has(df, name)
    ]
    out = (
        [f"**Deploy {what}**"]
        if choice.recommended
        else [
            "**No estimator meets the budget"
            + "".join(f" and {x}" for x in limits)
            + ".** The best-scoring "
            + ("exported " if best["export"] == "ok" else "")
            + f"one, not recommended: {what}"
        ]
    )
    out += _tie_lines(choice)
    passed = [(e, w) for e, w in choice.passed_over if e != str(best["estimator"])]
    if not choice.recommended:
        own = [w for e, w in choice.passed_over if e == str(best["estimator"])]
        if own:
            out += ["", f"Not recommended: {own[0]}."]
        near = closest_line(df, primary)
        if near:
            out += ["", near]
    if passed:
        out += [
            "",
            "Passed over (higher or equal score):"
            if choice.recommended
            else "The others:",
            "",
        ]
        out += [f"- `{e}`: {w}{_load_note(df, e, w)}" for e, w in passed]
    if cost is not None:
        out += ["", *_cost_lines(df, cost, max_early_alarm_rate, limit)]
    out += ["", TIMING_RULE]
    return out


def closest_line(df: pd.DataFrame, primary: str) -> str:
    """When latency is what keeps every row out: the exported row nearest its budget, by
    how much, and what would make it fit ("" when the nearest row is within its budget).

    ``p99_unpaced_us`` (the same frames back to back, :mod:`slipkit.compare.costs`)
    tells which: within the budget there, the graph fits and the calls made after idle
    frames (cold caches) put it over, which only the gripper PC's own ``slipkit-run
    --check`` can settle; over there too, the graph itself is that many times too slow.
    """
    if "p99_us" not in df or "budget_p99_us" not in df:
        return ""
    ok = df[df["export"].eq("ok")]
    margin = (ok["p99_us"].astype(float) / ok["budget_p99_us"].astype(float)).to_numpy()
    if not np.isfinite(margin).any():
        return ""
    r = ok.iloc[int(np.nanargmin(np.where(np.isfinite(margin), margin, np.nan)))]
    judged = judge_p99(float(r["p99_us"]), float(r["budget_p99_us"]))
    if judged.passed:
        return ""
    head = (
        f"Closest to the budget: `{r['estimator']}` ({primary} "
        f"{cell(r, primary, '{:.4g}')}), {judged.text()}"
    )
    back = float(r.get("p99_unpaced_us", math.nan))
    if not math.isfinite(back):
        return f"{head}: it needs a p99 {judged.margin:.2f} x lower."
    again = judge_p99(back, judged.budget_us)
    if again.passed:
        return (
            f"{head}; frames back to back {again.text()}: the graph fits, the calls "
            "after idle frames (cold caches on this machine) do not; run `slipkit-run "
            "BUNDLE --check` on the gripper PC, an idle core (`--cpus`), to decide."
        )
    return (
        f"{head}; frames back to back still {again.text()}: the graph itself needs "
        f"to be {again.margin:.2f} x cheaper."
    )


def _has(df: pd.DataFrame, limit_name: str) -> bool:
    """Whether any row defines the rate a limit holds (else the limit says nothing)."""
    column = "early_alarm_rate" if "early" in limit_name else "alarms_per_disturbance"
    return column in df and bool(
        pd.to_numeric(df[column], errors="coerce").notna().any()
    )


def _tie_lines(choice: DeployChoice) -> list[str]:
    """``Tie (within the spread over 3 seeds) with `b`, broken by lower delay (...)``."""
    if not choice.tied:
        return []
    others = ", ".join(f"`{e}`" for e in choice.tied)
    return [
        "",
        f"Tie (within the spread over {choice.n_seeds} seeds: the difference of the "
        f"means is no larger than the larger standard deviation) with {others}, "
        f"broken by {choice.tie_break}.",
    ]


def _event_note(row: pd.Series, limit: float | None) -> str:
    """``; slips detected 90 %, early alarms 10 % of trials (limit 25 %), false alarms
    0.8 /min`` (empty for a row without trial events)."""
    rate = _float(row.get("early_alarm_rate"))
    detected = _float(row.get("detected_rate"))
    if not (math.isfinite(rate) or math.isfinite(detected)):
        return ""
    parts = []
    if math.isfinite(detected):
        parts.append(f"slips detected {detected * 100:.0f} %")
    if math.isfinite(rate):
        parts.append(
            f"early alarms in {rate * 100:.0f} % of test trials"
            + ("" if limit is None else f" (limit {limit * 100:g} %)")
        )
    fa = _float(row.get("false_alarms_per_min"))
    if math.isfinite(fa):
        parts.append(f"false alarms {fa:.3g} /min")
    return "; " + ", ".join(parts)


def _float(value: Any) -> float:
    try:
        return math.nan if value is None else float(value)
    except (TypeError, ValueError):
        return math.nan


def _cost_lines(
    df: pd.DataFrame,
    cost: Cost,
    max_early_alarm_rate: float | None,
    max_alarms_per_disturbance: float | None,
) -> list[str]:
    """How a detection verdict is decided: the cost, the limits, which trials chose
    each operating point, and slips of unknown onset."""
    limits = [
        f"early alarms in at most {v * 100:g} % of the test trials"
        if k == "early"
        else f"alarms on at most {v * 100:g} % of the disturbances"
        for k, v in (
            ("early", max_early_alarm_rate),
            ("dist", max_alarms_per_disturbance),
        )
        if v is not None
    ]
    lines = [
        "Ranked on the trial cost (lower is better), never on per-sample accuracy: per "
        f"test trial a missed slip costs {cost.miss:g}, an alarm before the onset (any "
        f"alarm in a trial without slip) {cost.early_alarm:g}, and a detection "
        f"{cost.delay_ms:g} per ms of delay (at most a miss); the row's cost is the "
        "mean over test trials. "
        + (
            "A row is passed over when it has "
            + " or ".join(
                x.replace(
                    "early alarms in at most", "early alarms in more than"
                ).replace("alarms on at most", "alarms on more than")
                for x in limits
            )
            + "."
            if limits
            else "No limit on the rates."
        )
    ]
    sources = []
    if "operating_point_from" in df:
        sources = [
            str(v)
            for v in dict.fromkeys(df["operating_point_from"])
            if isinstance(v, str) and v
        ]
    if sources:
        lines += [
            "",
            "Each operating point (threshold, debounce) was chosen by that cost on "
            + "; ".join(f"`{x}`" for x in sources)
            + " (the training side only); the test split was scored once, at it.",
        ]
    unknown = (
        pd.to_numeric(df["unknown_onset_trials"], errors="coerce").max()
        if "unknown_onset_trials" in df
        else math.nan
    )
    if math.isfinite(float(unknown)) and unknown > 0:
        lines += [
            "",
            f"{unknown:.0f} test slip(s) have an unknown onset: they are scored on "
            "detected / not detected only (no early alarm, delay or false alarms).",
        ]
    return lines


def _load_note(df: pd.DataFrame, estimator: str, why: str) -> str:
    """For a row passed over on its p99: whether its quietest block met the budget (the
    machine's load, not the estimator, put it over: re-measure on an idle machine)."""
    if not why.startswith("p99 ") or "p99_quiet_us" not in df:
        return ""
    row = df[df["estimator"].astype(str) == estimator]
    if row.empty:
        return ""
    quiet = float(row["p99_quiet_us"].iloc[0])
    budget = float(row["budget_p99_us"].iloc[0])
    if not (math.isfinite(quiet) and math.isfinite(budget)) or quiet > budget:
        return ""
    return (
        f" (its quietest block's p99 {quiet:.1f} us meets the budget: the machine's "
        "load put it over; re-measure on an idle machine)"
    )


def _over_seeds(row: pd.Series) -> str:
    n = row.get("n_seeds")
    return (
        f" (mean ± std over {int(n)} seeds)"
        if isinstance(n, int | float) and math.isfinite(n) and n > 1
        else ""
    )


#: how the verdict treats latency, stated under every verdict: the runtime's one rule,
#: and what the quietest block tells of a row put over the budget
TIMING_RULE = (
    RULE_TEXT
    + " A row over budget whose quietest block meets the budget is marked as put over "
    "by the machine's load."
)


def _disturbance_note(row: pd.Series, limit: float | None) -> str:
    """``, fires on 0 % of 13 disturbances (limit 10 %)`` (empty without a count)."""
    rate = disturbance_rate(row)
    if not math.isfinite(rate):
        return ""
    try:
        n = float(row.get("disturbances"))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        n = math.nan
    of = f"of {n:.0f} disturbances" if math.isfinite(n) else "of the disturbances"
    return f", fires on {rate * 100:.0f} % {of}" + (
        "" if limit is None else f" (limit {limit * 100:g} %)"
    )


def verdict(
    df: pd.DataFrame,
    primary: str,
    *,
    max_alarms_per_disturbance: float | None = None,
    max_early_alarm_rate: float | None = None,
    cost: Cost | None = None,
) -> list[str]:
    """Which estimator to deploy (:func:`deploy_lines`), and what each step along the Pareto front costs."""
    out = deploy_lines(
        df,
        primary,
        max_alarms_per_disturbance=max_alarms_per_disturbance,
        max_early_alarm_rate=max_early_alarm_rate,
        cost=cost,
    )
    if out == ["No estimator produced a score."]:
        return out
    front = df[df["pareto"].astype(bool)].sort_values("p99_us")
    unit = metric_unit(primary, list(df.columns))
    if len(front) > 1:
        out.append("")
        out.append(
            "Along the Pareto front (p99 compute, cheapest first), what the next step of "
            "accuracy costs:"
        )
        out.append("")
        prev = None
        for _, r in front.iterrows():
            if prev is not None:
                d_score = float(r["score"]) - float(prev["score"])
                d_us = float(r["p99_us"]) - float(prev["p99_us"])
                d_delay = float(r["delay_ms"]) - float(prev["delay_ms"])
                delay = (
                    f", {d_delay:+.1f} ms detection delay"
                    if math.isfinite(d_delay)
                    else ""
                )
                if score_of({primary: 1.0}, primary) < 0:  # lower is better: own units
                    gain = f"{-d_score:+.4g} {unit + ' ' if unit else ''}{primary}"
                    per = (
                        f" ({d_us / d_score:.3g} {per_unit('us', unit) if unit else 'us per unit of ' + primary})"
                        if d_score > 0
                        else ""
                    )
                else:  # a rate in [0, 1]: percentage points
                    gain = f"{d_score * 100:+.2f} points of {primary}"
                    per = (
                        f" ({d_us / (d_score * 100):.2f} us per point)"
                        if d_score > 0
                        else ""
                    )
                out.append(
                    f"- `{prev['estimator']}` -> `{r['estimator']}`: {gain} for "
                    f"{d_us:+.1f} us p99 per frame{per}{delay}"
                )
            prev = r
    return out


def write_report(
    folder: Path,
    *,
    name: str,
    description: str,
    primary: str,
    df: pd.DataFrame,
    plots: Mapping[str, Path | None],
    command: str,
    config_yaml: str,
    split_note: str,
    summaries: Mapping[str, str],
    seconds: float,
    verdict_limits: Mapping[str, float | None] | None = None,
    cost: Cost | None = None,
) -> Path:
    """Write ``folder/report.md`` and return its path (``verdict_limits``: the checked
    ``verdict:`` of the comparison, :func:`slipkit.compare.table.verdict_limits`;
    ``cost``: its trial cost when the comparison ranks on it)."""
    reg_cols = [
        c
        for c in df.columns
        if c.startswith(("rmse_", "smse_")) and not c.endswith(("_std", "_ci"))
    ]
    lines = [
        f"# Comparison: {name}",
        "",
        description.strip(),
        "",
        f"Estimators: {len(df)}; primary score: `{primary}` "
        + (
            "(lower is better; `score` is its negative)"
            if score_of({primary: 1.0}, primary) < 0
            else "(higher is better)"
        )
        + f". {split_note} Wall time {seconds:.0f} s.",
        "",
        "## Verdict",
        "",
        *verdict(df, primary, **dict(verdict_limits or {}), cost=cost),
        "",
        "## Accuracy",
        "",
        markdown_table(df, MAIN),
        "",
    ]
    if reg_cols:
        spec = [("estimator", "estimator", "{}")] + [(c, c, "{:.4g}") for c in reg_cols]
        lines += ["Per axis (test side):", "", markdown_table(df, spec), ""]
    control_cols = [c for c, _, _ in CONTROLS[3:] if c in df]
    if control_cols and df[control_cols].notna().any().any():
        lines += [
            "## Controls",
            "",
            "Per window and per sequence (majority vote of a trial's windows), beside what "
            "the same model scores from each trial's first frame only (static contact), "
            "from dynamics only (each trial's first frame subtracted) and what the "
            "training side's majority class scores. A headline close to the first-frame "
            "control reads the static contact, not the slip.",
            "",
            markdown_table(df, CONTROLS),
            "",
        ]
    lines += ["## Cost", "", markdown_table(df, COST), ""]
    titles = {
        "pareto": "Accuracy against compute per frame (Pareto front)",
        "accuracy_vs_time": "Accuracy against time relative to the slip onset",
        "accuracy_vs_width": "Accuracy against window length",
        "roc": "ROC curves and the chosen thresholds",
        "delays": "Detection delay",
        "latency": "Per-frame latency against the budget",
        "confusion": "Confusion matrices",
        "search": "Accuracy against the number of search trials",
    }
    lines += ["## Plots", ""]
    for key, title in titles.items():
        path = plots.get(key)
        if path is not None:
            lines += [f"### {title}", "", f"![{title}]({path.name})", ""]
    lines += [
        "## How this was made",
        "",
        "```",
        command,
        "```",
        "",
        "Every estimator ran through the same task (`slipkit train`'s code path) with the same seed; "
        "its run folder is under `runs/<estimator>/` (metrics.json, the task's tables and plots). "
        "Compute per frame: each run exported to an ONNX bundle (`slipkit export`'s functions), "
        "its held-out replay frames pushed one by one through `slipkit.runtime.StreamLoop` "
        "(onnxruntime, 1 thread, batch 1, after warm-up); p50 / p99 of frame arrival -> decision.",
        "",
        "<details><summary>Each task's own summary</summary>",
        "",
    ]
    for est, text in summaries.items():
        lines += [f"**{est}**", "", "```", text.rstrip(), "```", ""]
    lines += [
        "</details>",
        "",
        "<details><summary>Resolved config</summary>",
        "",
        "```yaml",
        config_yaml.rstrip(),
        "```",
        "",
        "</details>",
        "",
    ]
    path = folder / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


__all__ = [
    "CONTROLS",
    "TIMING_RULE",
    "cell",
    "deploy_lines",
    "margin_text",
    "markdown_table",
    "verdict",
    "write_report",
]
