"""The BioTac force regression's comparison adapter: per-axis RMSE and SMSE -> one row
(registered with :mod:`slipkit.compare.adapters`)."""

from __future__ import annotations

import math
from typing import Any

from slipkit.compare.adapters import Evaluation, RunView, register_adapter
from slipkit.families.biotac.force_task import ForceRegression


def adapt_force(view: RunView) -> Evaluation:
    """BioTac force (N) per axis (:class:`ForceRegression`)."""
    m = view.metrics
    test = m["test"]
    row: dict[str, Any] = {
        "rmse": float(test["rmse_mean"]),
        "smse": float(test["smse_mean"]),
        "window_frames": 1,
        "decision_frames": 1,
    }
    for axis, v in test["rmse"].items():
        row[f"rmse_{axis}"] = float(v)
    for axis, v in test["smse"].items():
        row[f"smse_{axis}"] = float(v)
    task: Any = view.task
    rate = view.dataset.streams[task.stream].rate_hz
    row["window_ms"] = 1000.0 / float(rate) if rate else math.nan
    return Evaluation(row=row, split=m["split"])


register_adapter(ForceRegression, adapt_force)
