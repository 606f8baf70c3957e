"""TacTip's comparison adapters (registered with :mod:`slipkit.compare.adapters`): the
frame task's metrics -> one row, and the TacTip trial-event measure of a stream
detector's run (first alarm within :data:`~slipkit.compare.adapters.ON_TIME_FRAMES`
frames of the onset) on the camera frames the frame task scores."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from slipkit.compare.adapters import (
    Evaluation,
    RunView,
    _event_delays,
    _roc,
    binary_rates,
    event_row,
    frame_task_events,
    register_adapter,
    register_trial_events,
    stream_task_events,
)
from slipkit.evaluate.events import alarm_indices
from slipkit.families.tactip.task import TacTipFrames
from slipkit.features.pins import SLIP


def adapt_tactip(view: RunView) -> Evaluation:
    """TacTip per-frame slip / static (:class:`~slipkit.families.tactip.task.TacTipFrames`)."""
    task: Any = view.task
    test = view.metrics["test"]
    labels = [str(x) for x in test["labels"]]
    cm = np.asarray(test["confusion"])
    row: dict[str, Any] = binary_rates(cm) if labels[-1] == SLIP else {}
    det = test["detection"]
    rate = task.rate_hz(view.dataset)
    k = int(det["debounce_k"])  # the deployed debounce (chosen on validation)
    preds = pd.read_csv(view.folder / "test_predictions.csv")
    events, event_table = frame_task_events(preds, SLIP, k)
    row.update(events)
    point = dict(view.metrics.get("operating_point") or {})
    row.update(event_row(test["operating_point"], str(point.get("from", ""))))
    delays = (
        [float(v) for v in _event_delays(view.folder / "test_events.csv")]
        if (view.folder / "test_events.csv").is_file()
        else [d * 1000.0 / rate for d in det["delay_frames"] if d is not None]
    )
    row.update(
        window_frames=2,  # a pin velocity is the difference of two frames
        window_ms=2 * 1000.0 / rate,
        decision_frames=2 + k - 1,
    )
    roc = None
    if hasattr(view.model, "decision_function"):
        test_ds = view.dataset.subset(list(view.metrics["split"]["test"]))
        feats = task.features(test_ds)
        scores = np.asarray(view.model.decision_function(feats.X), dtype=float)
        classes = [str(c) for c in getattr(view.model, "classes_", ["", SLIP])]
        if (
            classes[-1] != SLIP
        ):  # a binary decision_function is positive for classes_[1]
            scores = -scores
        roc = _roc(
            feats.y == SLIP,
            scores,
            (row.get("fpr", math.nan), row.get("tpr", math.nan)),
            "frames",
        )
        if roc is not None:
            row["roc_auc"] = roc["auc"]
    search = None
    history = (view.metrics.get("search") or {}).get("history")
    if history:
        search = pd.DataFrame(history)[["number", "value"]]
        row["search_trials"] = len(search)
    return Evaluation(
        row=row,
        confusion=(labels, cm),
        roc=roc,
        delays_ms=delays,
        split=view.metrics["split"],
        search=search,
        trial_events=event_table,
    )


def tactip_trial_events(
    view: RunView, rec: Any, scores: np.ndarray, row: Mapping[str, Any]
) -> tuple[dict[str, Any], pd.DataFrame | None]:
    """The TacTip event measure of a stream detector's run, on the frames the frame task
    scores (:mod:`slipkit.compare.adapters` notes); the task's own rule: slip where the
    score reaches the threshold."""
    fired = np.zeros(len(scores), dtype=bool)
    k = int(row["debounce_k"]) if math.isfinite(row["debounce_k"]) else 1
    for a, b in rec.bounds():  # the deployed rule: the k-th sample >= threshold
        fired[a + alarm_indices(scores[a:b], float(view.model.threshold_), k)] = True
    return stream_task_events(rec.t, fired, rec.bounds(), rec.onset_s, rec.trial_ids)


register_adapter(TacTipFrames, adapt_tactip)
register_trial_events("tactip", tactip_trial_events)
