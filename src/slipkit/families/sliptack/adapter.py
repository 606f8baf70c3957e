"""SlipTack's comparison adapters: the speed and acceleration tasks' metrics -> one row
(registered with :mod:`slipkit.compare.adapters`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from slipkit.compare.adapters import Evaluation, RunView, _num, register_adapter
from slipkit.families.sliptack.task import SlipTackAccel, SlipTackSpeed


def adapt_sliptack_speed(view: RunView) -> Evaluation:
    """SlipTack speed (mm/s) from the stick-slip frequency (:class:`SlipTackSpeed`)."""
    m = view.metrics
    overall = m["test"]["overall"]
    row: dict[str, Any] = {
        "rmse": _num(overall["rmse_mm_s"]),
        "rmse_speed": _num(overall["rmse_mm_s"]),
    }
    model = view.model
    if isinstance(model, Mapping):  # the speed task fits one estimator per material
        model = next(iter(model.values()))
    p = model.get_params()
    window = int(p.get("window", 1))
    rate = float(p.get("rate_hz", math.nan))
    row.update(
        window_frames=window, window_ms=window * 1000.0 / rate, decision_frames=window
    )
    return Evaluation(row=row, split=m["split"])


def adapt_sliptack_accel(view: RunView) -> Evaluation:
    """SlipTack drop acceleration (m/s^2) (:class:`SlipTackAccel`): the estimator's feature."""
    m = view.metrics
    p = view.model.get_params()
    feature = str(p.get("feature", "deflection"))
    test = m["test"][feature]
    row: dict[str, Any] = {
        "rmse": _num(test["rmse_m_s2"]),
        "rmse_accel": _num(test["rmse_m_s2"]),
    }
    frames = (
        int(p.get("smooth_frames", 1))
        if feature == "deflection"
        else int(p.get("slope_frames", 1))
        + int((p.get("speed") or {}).get("window", 0))
    )
    rate = float(p.get("rate_hz", math.nan))
    row.update(
        window_frames=frames, window_ms=frames * 1000.0 / rate, decision_frames=frames
    )
    return Evaluation(row=row, split=m["split"])


register_adapter(SlipTackSpeed, adapt_sliptack_speed)
register_adapter(SlipTackAccel, adapt_sliptack_accel)
