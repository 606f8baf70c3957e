"""DAVIS's comparison adapter: the release task's pooled 20 ms bins and trial events -> one
row (registered with :mod:`slipkit.compare.adapters`)."""

from __future__ import annotations

import math
from typing import Any

import pandas as pd

from slipkit.compare.adapters import (
    Evaluation,
    RunView,
    _num,
    event_row,
    register_adapter,
)
from slipkit.families.davis.task import DavisRelease


def adapt_davis(view: RunView) -> Evaluation:
    """DAVIS 20 ms bins (:class:`DavisRelease`): pooled TP / FP / FN."""
    m = view.metrics
    pooled = m["test"]["pooled"]
    tp, fp, fn = float(pooled["tp"]), float(pooled["fp"]), float(pooled["fn"])
    lat = m["test"]["latency_ms"]
    row: dict[str, Any] = {
        "f1": _num(pooled["f1"]),
        "tpr": _num(pooled["sensitivity"]),
        "fnr": fn / (tp + fn) if tp + fn else math.nan,
        "delay_ms": _num(lat.get("median")),
        "missed": int(lat.get("missed", 0)),
        "n_slips": int(m["test"]["n_trials"]),
    }
    frame_s = float(view.model.get_params().get("frame_s", math.nan))
    delays: list[float] = []
    trials_path, frames_path = (
        view.folder / "davis_trials.csv",
        view.folder / "test_frames.csv",
    )
    if trials_path.is_file() and frames_path.is_file():
        t = pd.read_csv(trials_path)
        delays = [float(v) for v in t["latency_ms"] if math.isfinite(float(v))]
        # Non-slip time: each test trial's recorded span minus its slip (onset -> end).
        span = pd.read_csv(frames_path).groupby("trial_id")["t_end_s"].max()
        slip = (t["end_s"] - t["onset_s"]).clip(lower=0).sum()
        minutes = (float(span.sum()) - float(slip)) / 60.0
        # The task scores bins, not alarms: a false-positive bin is the alarm counted here.
        row["false_alarms_per_min"] = fp / minutes if minutes > 0 else math.nan
    if "operating_point" in m["test"]:  # trial events: each slip frame an alarm
        point = dict(m.get("operating_point") or {})
        row.update(event_row(m["test"]["operating_point"], str(point.get("from", ""))))
    # a decision: the chosen debounce's consecutive frames
    k = int((m.get("operating_point") or {}).get("debounce_k") or 1)
    row.update(window_frames=1, window_ms=frame_s * 1000.0, decision_frames=k)
    return Evaluation(row=row, delays_ms=delays, split=m["split"])


register_adapter(DavisRelease, adapt_davis)
