"""What the stream-detection task prints and plots: the operating point line, the summary
blocks, the ROC figure."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray

from slipkit.evaluate.events import (
    MINIMISED,
)

FloatArray = NDArray[np.float64]


def _direction(objective: str) -> str:
    """``minimize`` for a cost, delay or rate of mistakes, else ``maximize``."""
    return "minimize" if objective.rsplit(".", 1)[-1] in MINIMISED else "maximize"


def _plain(v: Any) -> Any:
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    return str(v)


def _pct(v: Any) -> str:
    return (
        "n/a" if v is None or not math.isfinite(float(v)) else f"{100 * float(v):.2f} %"
    )


def _num(v: Any, fmt: str = ".4g") -> str:
    return "n/a" if v is None or not math.isfinite(float(v)) else format(float(v), fmt)


def operating_point_line(name: str, test: Mapping[str, Any], unit: str = "") -> str:
    """One line: ``<name> at threshold <t> <unit>, debounce 2: slips detected 36/40
    (90 %), early alarms 3/40 trials (8 %), false alarms 0.8 /min, delay median 42 ms
    (p90 80 ms), cost 0.21``."""
    op = test["operating_point"]
    n_slips, n = int(op["n_slips"]), int(op["event_trials"])
    detected = n_slips - int(op["missed"])
    share = f" ({_num(100.0 * detected / n_slips, '.0f')} %)" if n_slips else ""
    rate = _float(op.get("early_alarm_rate"))
    early = (
        "early alarms n/a (onsets unknown)"
        if not math.isfinite(rate)
        else f"early alarms {_pct0(rate)} of trials"
    )
    unknown = int(op.get("unknown_onset_trials") or 0)
    note = f" ({unknown} slips of unknown onset: detection only)" if unknown else ""
    ba = _float(op.get("trial_balanced_accuracy"))
    if unknown and math.isfinite(ba):
        note += f", balanced accuracy over trials {ba:.3f}"
    return (
        f"{name} at threshold {_num(op.get('threshold', test.get('threshold')))}"
        f"{' ' + unit if unit else ''}, debounce {int(op['debounce_k'])}: slips "
        f"detected {detected}/{n_slips}{share}{note}, {early}, false alarms "
        f"{_num(op['false_alarms_per_min'], '.3g')} /min, delay median "
        f"{_num(op['delay_ms'], '.0f')} ms (p90 {_num(op['delay_p90_ms'], '.0f')} ms), "
        f"cost {_num(op['cost'], '.3g')} over {n} trials"
    )


def _float(v: Any) -> float:
    try:
        return math.nan if v is None else float(v)
    except (TypeError, ValueError):
        return math.nan


def _pct0(v: float) -> str:
    return f"{100 * v:.0f} %"


def _summary_block(name: str, b: Mapping[str, Any], group_by: str | None) -> list[str]:
    te, paper, unit = b["test"], b.get("paper", {}), b.get("unit", "")

    def beside(key: str, fmt: Any) -> str:
        return f" (paper {fmt(paper[key])})" if key in paper else ""

    s, ev, tr = te["samples"], te["events"], te["trials"]
    lines = [
        f"{name} ({b['estimator']} on {b['stream']}): threshold {_num(te['threshold'])} "
        f"{unit} from {b['threshold_from']}{beside('threshold', _num)}",
        *_point_lines(b.get("operating_point")),
        f"  test samples: AUC {_num(s['auc'], '.4f')}, TPR {_pct(s['tpr'])}, "
        f"TNR {_pct(s['tnr'])}, FPR {_pct(s['fpr'])}, FNR {_pct(s['fnr'])}",
        f"  test events: AUC {_num(ev['auc'], '.4f')}{beside('auc', _num)}, "
        f"sensitivity {_pct(ev['sensitivity'])}{beside('tpr', _pct)} "
        f"({ev['tp']}/{ev['n_events']}), specificity {_pct(ev['specificity'])}"
        f"{beside('tnr', _pct)} ({ev['fp']} of {ev['n_negative_windows']} non-slip "
        "windows fired)",
        f"  test trials: {tr['tp']}/{tr['n_slip']} slips detected, {tr['fp']}/{tr['n']} "
        f"fired before the onset; latency from onset {_num(te['latency_ms']['mean'], '.1f')}"
        f" +- {_num(te['latency_ms']['sd'], '.1f')} ms",
    ]
    unknown = int((te.get("operating_point") or {}).get("unknown_onset_trials") or 0)
    if unknown and not tr["n_slip"]:
        # no onsets: the line above has no slip to count; the trial events are the
        # operating point's (printed first), where a slip is detected by any alarm
        lines[-1] = (
            f"  test trials: no slip onsets ({unknown} slip trials scored on detection "
            "only, at the operating point above)"
        )
    if "disturbances" in te:
        d = te["disturbances"]
        lines.append(
            f"  disturbances: {d['fired']} of {d['n']} fired"
            + (f" (paper: {paper['disturbances']})" if "disturbances" in paper else "")
        )
    if "at_paper_threshold" in te:
        a = te["at_paper_threshold"]
        lines.append(
            f"  at the paper's threshold {_num(a['threshold'])} {unit}: events sensitivity "
            f"{_pct(a['events']['sensitivity'])}, specificity {_pct(a['events']['specificity'])}"
            + (
                f", disturbances fired {a['disturbances']['fired']}/{a['disturbances']['n']}"
                if "disturbances" in a
                else ""
            )
        )
    if "vs_reference_ms" in te:
        ref = te["vs_reference_ms"]
        pref = paper.get("reference_ms", {})
        for g, st in ref.items():
            p = pref.get(g)
            ptxt = f" (paper {p[0]:+.1f} +- {p[1]:.1f} ms)" if p else ""
            label = "all trials" if g == "all" else f"{group_by}={g}"
            lines.append(
                f"  vs reference onset, {label}: {_num(st['mean'], '+.1f')} +- "
                f"{_num(st['sd'], '.1f')} ms over {st['n']}{ptxt}"
            )
    return lines


def _point_lines(op: Mapping[str, Any] | None) -> list[str]:
    """Where the operating point came from and what it cost there (one or two lines)."""
    if not op:
        return []
    lines = [
        f"  operating point: threshold {_num(op.get('threshold'))}, debounce "
        f"{op.get('debounce_k')}, from {op.get('from')}"
        + (
            f" (validation cost {_num(op['validation'].get('cost'), '.3g')})"
            if op.get("validation")
            else ""
        )
    ]
    if op.get("within_limits") is False:
        lines.append(f"  NOT within the limits: {op.get('note')}")
    return lines


def _plot_roc(curves: Mapping[str, Mapping[str, Any]], path: Path) -> None:
    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    for name, cv in curves.items():
        for unit, (fpr, tpr) in cv.items():
            ax.plot(fpr, tpr, label=f"{name} ({unit})")
    ax.plot([0, 1], [0, 1], color="0.7", lw=0.8, ls="--")
    ax.set_xlabel("false positive rate")
    ax.set_ylabel("true positive rate")
    ax.set_title("ROC on the test trials")
    if ax.get_legend_handles_labels()[0]:  # no curve without slip samples (no onsets)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
