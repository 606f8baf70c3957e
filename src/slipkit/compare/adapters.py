"""Per-task adapters: one task's metrics (and its fitted estimator) -> one unified row.

The tasks (:mod:`slipkit.train.tasks`) each score in their family's terms (TacTip
frames, windows of electrodes, stream samples and events, force axes, SlipTack
speeds, DAVIS bins). A comparison needs the same columns for every estimator, so
each adapter reads what its task already wrote (``metrics.json``, the predictions
table) and, only where the task keeps no scores, asks the fitted estimator again on
the same test trials (ROC curves). Nothing here re-implements a task.

Unified columns (:data:`ROW_COLUMNS`; a missing one is NaN):

* frame level: ``accuracy``, ``balanced_accuracy``, ``f1`` (the slip class's F1 when
  the task has a slip class, else macro F1), ``tpr``, ``tnr``, ``fpr``, ``fnr``,
  ``roc_auc`` (slip as the positive class; a binary slip-type task takes its second
  class);
* trial events (every detection task, :mod:`slipkit.evaluate.events`, at the deployed
  operating point): ``detected_rate`` (slips detected / slip trials),
  ``early_alarm_rate`` (test trials with an alarm before the onset / trials where it
  is defined), ``false_alarms_per_min`` (alarms declared in non-slip time per minute
  of it), ``disturbances`` (test disturbances: bumps, knocks with no slip, where the
  task's data marks them) and ``alarms_per_disturbance`` (the share of them with an
  alarm; NaN where the data marks none), ``delay_ms`` (median delay from the onset to
  the first alarm after it) and ``delay_p90_ms``, ``missed``, ``n_slips``,
  ``event_trials`` (test trials of known outcome), ``cost`` (mean trial cost, lower is
  better), the operating point ``threshold`` and ``debounce_k`` and
  ``operating_point_from`` (which trials chose it);
* regression: ``rmse`` and ``smse`` (means over axes) and ``rmse_<axis>``,
  ``smse_<axis>`` per axis (force N; SlipTack speed mm/s or acceleration m/s^2);
* the window: ``window_frames`` and ``window_ms`` (sensor frames the estimator reads
  for one decision) and ``decision_frames`` (frames from the first one it reads to a
  declared slip, with the online debounce).

Trial events (TacTip's target measure; beside :data:`ROW_COLUMNS`, see
:func:`trial_events`): the TacTip frame task (SVMs) labels 4 slip frames per trial and
the stream task (pin-motion detector) every frame from the onset on, so their frame
rates measure two different things. Both tasks' decision rules (the frame task's
debounced online rule, the detector's own ``consecutive`` frames) give each test trial
a first alarm, on the same camera frames of the same trials, so the comparison ranks
them on ``on_time_rate``: the fraction of test trials whose slip's first alarm comes
0 to :data:`ON_TIME_FRAMES` frames after the onset frame (no alarm before it), a trial
without slip counting when nothing fires. Beside it: ``no_early_alarm_rate`` (trials
with no alarm before the onset, or none at all without slip), ``late_slips`` (first
alarm later than that), ``event_trials``; ``missed`` and ``delay_ms`` stay the tasks'
own.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import slipkit.families as _families
from slipkit._registry import Registry
from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.train.task import Task

#: unified metric columns, in table order (costs are added by :mod:`.costs`)
ROW_COLUMNS = (
    "accuracy",
    "balanced_accuracy",
    "f1",
    "tpr",
    "tnr",
    "fpr",
    "fnr",
    "roc_auc",
    "detected_rate",
    "early_alarm_rate",
    "false_alarms_per_min",
    "alarms_per_disturbance",
    "delay_ms",
    "delay_p90_ms",
    "missed",
    "n_slips",
    "event_trials",
    "disturbances",
    "cost",
    "threshold",
    "debounce_k",
    "operating_point_from",
    "rmse",
    "smse",
    "window_frames",
    "window_ms",
    "decision_frames",
)


#: frames after the onset frame within which a slip's first alarm is on time (the
#: TacTip target: "within 2 frames of onset, with no alarm before onset")
ON_TIME_FRAMES = 2


@dataclass
class Evaluation:
    """One estimator's scores on the shared test side, in comparison terms.

    Attributes
    ----------
    row : dict
        Unified columns (:data:`ROW_COLUMNS` and per-axis ``rmse_<axis>``).
    confusion : tuple of (list of str, ndarray) or None
        Class labels and the test confusion matrix (rows true, columns predicted).
    roc : dict or None
        ``{"fpr": ndarray, "tpr": ndarray, "point": (fpr, tpr) or None, "unit": str}``;
        ``point`` is the operating point the estimator's threshold chose.
    delays_ms : list of float
        Detection delay of every detected test slip, ms.
    vs_time : DataFrame or None
        ``t_rel_s`` (s from the onset) and ``accuracy`` of test windows.
    vs_width : DataFrame or None
        ``ms`` (window length) and ``accuracy``, each width refitted by the task.
    split : object
        What the task recorded as its split (checked equal across estimators).
    search : DataFrame or None
        ``number`` and ``value`` (CV score) of each in-run search trial, in order.
    trial_events : DataFrame or None
        Per test trial (TacTip): ``trial_id``, ``onset_frame`` and ``first_alarm_frame``
        (velocity frames, NaN: none), ``outcome`` (:func:`trial_events`).
    """

    row: dict[str, Any] = field(default_factory=dict)
    confusion: tuple[list[str], np.ndarray] | None = None
    roc: dict[str, Any] | None = None
    delays_ms: list[float] = field(default_factory=list)
    vs_time: pd.DataFrame | None = None
    vs_width: pd.DataFrame | None = None
    split: Any = None
    search: pd.DataFrame | None = None
    trial_events: pd.DataFrame | None = None


@dataclass(frozen=True)
class RunView:
    """What an adapter may read: the task, its metrics and files, the fitted estimator, the data."""

    task: Task
    metrics: Mapping[str, Any]
    folder: Path
    model: Any
    dataset: Dataset


Adapter = Callable[[RunView], Evaluation]
_ADAPTERS: Registry[type, Adapter] = Registry(
    "comparison adapter", error=SlipkitError, n_args=1, key_type=type
)


def register_adapter(task_cls: type, fn: Adapter, *, overwrite: bool = False) -> None:
    """Use ``fn`` for tasks of ``task_cls`` (and subclasses without their own); a second
    adapter for the same class is refused unless ``overwrite=True``."""
    _ADAPTERS.register(task_cls, fn, overwrite=overwrite)


#: A family's trial-event measure of a stream detector's run: ``(view, recordings,
#: test scores, row so far) -> (columns, per-trial table)``, by the dataset's sensor.
TrialEvents = Callable[
    [RunView, Any, np.ndarray, Mapping[str, Any]],
    tuple[dict[str, Any], pd.DataFrame | None],
]
_TRIAL_EVENTS: Registry[str, TrialEvents] = Registry(
    "stream detector trial-event measure", error=SlipkitError, n_args=4, key_type=str
)


def register_trial_events(
    sensor: str, fn: TrialEvents, *, overwrite: bool = False
) -> None:
    """Score the stream detectors of ``sensor``'s datasets also by ``fn``'s trial events
    (:func:`adapt_detection` adds its columns and table, e.g. TacTip's on-time rate)."""
    _TRIAL_EVENTS.register(sensor, fn, overwrite=overwrite)


def adapt(view: RunView) -> Evaluation:
    """The unified evaluation of ``view`` by the adapter of its task's class (family
    folders' adapters, ``slipkit.families.PLUGIN_MODULES["adapters"]``, register first)."""
    _families.load_plugins("adapters")
    fn = _ADAPTERS.for_class(type(view.task))
    if fn is not None:
        ev = fn(view)
        for col in ROW_COLUMNS:
            ev.row.setdefault(col, math.nan)
        return ev
    raise TypeError(
        f"no comparison adapter for task {type(view.task).__name__}; register one with "
        "slipkit.compare.adapters.register_adapter"
    )


# -- helpers ----------------------------------------------------------------------------


def binary_rates(cm: np.ndarray) -> dict[str, float]:
    """Frame rates of a 2 x 2 confusion matrix ``[[tn, fp], [fn, tp]]`` (positive second)."""
    (tn, fp), (fn, tp) = np.asarray(cm, dtype=float)
    n = tn + fp + fn + tp

    def div(a: float, b: float) -> float:
        return a / b if b else math.nan

    tpr, tnr = div(tp, tp + fn), div(tn, tn + fp)
    return {
        "accuracy": div(tp + tn, n),
        "balanced_accuracy": (tpr + tnr) / 2,
        "f1": div(2 * tp, 2 * tp + fp + fn),
        "tpr": tpr,
        "tnr": tnr,
        "fpr": div(fp, fp + tn),
        "fnr": div(fn, fn + tp),
    }


def _num(value: Any) -> float:
    return math.nan if value is None else float(value)


def _roc(
    y: np.ndarray, s: np.ndarray, point: tuple[float, float] | None, unit: str
) -> dict[str, Any] | None:
    from sklearn.metrics import roc_auc_score, roc_curve

    y = np.asarray(y).astype(int)
    if len(np.unique(y)) != 2:
        return None
    s = np.asarray(s, dtype=np.float64)
    s = np.where(np.isfinite(s), s, np.finfo(np.float64).min)
    fpr, tpr, _ = roc_curve(y, s)
    return {
        "fpr": fpr,
        "tpr": tpr,
        "auc": float(roc_auc_score(y, s)),
        "point": point,
        "unit": unit,
    }


def trial_events(
    trial_ids: Sequence[str],
    onset_frames: Sequence[int | None],
    first_alarms: Sequence[int | None],
    *,
    on_time_frames: int = ON_TIME_FRAMES,
) -> tuple[dict[str, Any], pd.DataFrame]:
    """Each trial's first alarm against its onset: the event columns and the per-trial table.

    Parameters
    ----------
    trial_ids : sequence of str
        The test trials.
    onset_frames : sequence of int or None
        Each trial's onset frame (None: no slip in the trial).
    first_alarms : sequence of int or None
        The frame of each trial's first alarm, in the same frames (None: none).
    on_time_frames : int
        Frames after the onset frame that are still on time.

    Returns
    -------
    row : dict
        ``on_time_rate`` (trials on time / trials: a slip whose first alarm is 0 to
        ``on_time_frames`` frames after its onset frame, or a trial without slip and
        without alarm), ``no_early_alarm_rate`` (trials without an alarm before the
        onset, or without any alarm when there is no slip / trials), ``late_slips``
        (first alarm later than ``on_time_frames``), ``event_trials``.
    table : DataFrame
        ``trial_id``, ``onset_frame``, ``first_alarm_frame`` (NaN: none), ``outcome``:
        ``on_time``, ``early``, ``late``, ``missed`` (a slip trial) or ``quiet``,
        ``false_alarm`` (a trial without slip).
    """
    outcomes = []
    for onset, first in zip(onset_frames, first_alarms, strict=True):
        if onset is None:
            outcomes.append("quiet" if first is None else "false_alarm")
        elif first is None:
            outcomes.append("missed")
        elif first < onset:
            outcomes.append("early")
        else:
            outcomes.append("on_time" if first - onset <= on_time_frames else "late")
    n = len(outcomes)
    good = sum(o in ("on_time", "quiet") for o in outcomes)
    early = sum(o in ("early", "false_alarm") for o in outcomes)
    row = {
        "on_time_rate": good / n if n else math.nan,
        "no_early_alarm_rate": (n - early) / n if n else math.nan,
        "late_slips": sum(o == "late" for o in outcomes),
        "event_trials": n,
    }
    table = pd.DataFrame(
        {
            "trial_id": [str(t) for t in trial_ids],
            "onset_frame": [math.nan if v is None else v for v in onset_frames],
            "first_alarm_frame": [math.nan if v is None else v for v in first_alarms],
            "outcome": outcomes,
        }
    )
    return row, table


def _event_delays(path: Path) -> list[float]:
    """The finite ``delay_ms`` of a task's per-trial events table (ms)."""
    delays = pd.read_csv(path)["delay_ms"].to_numpy(float)
    return [float(v) for v in delays if math.isfinite(v)]


def _first(flags: np.ndarray) -> int | None:
    hit = np.flatnonzero(flags)
    return int(hit[0]) if len(hit) else None


def frame_task_events(
    table: pd.DataFrame, positive: str, debounce_k: int
) -> tuple[dict[str, Any], pd.DataFrame]:
    """:func:`trial_events` of a per-velocity-frame predictions table (TacTip frame task).

    The onset frame is a trial's first frame labelled ``positive`` (the task labels the
    onset's velocity frame and the next ``n_slip - 1``); the first alarm is the first
    frame of the debounced online rule (``debounce_k`` consecutive slip predictions),
    as the task's own detection delay.
    """
    from slipkit.models.online import first_detection

    ids, onsets, firsts = [], [], []
    for tid, g in table.groupby("trial_id", sort=False):
        ids.append(str(tid))
        onsets.append(_first((g["label"].astype(str) == positive).to_numpy()))
        pred = (g["pred"].astype(str) == positive).to_numpy()
        firsts.append(first_detection(pred, int(debounce_k)))
    return trial_events(ids, onsets, firsts)


def stream_task_events(
    t: np.ndarray,
    fired: np.ndarray,
    bounds: Sequence[tuple[int, int]],
    onset_s: np.ndarray,
    trial_ids: Sequence[str],
) -> tuple[dict[str, Any], pd.DataFrame]:
    """:func:`trial_events` of a stream detector's per-sample decisions (TacTip pins).

    Samples are camera frames; in the frame task's terms sample ``j + 1`` ends velocity
    frame ``j``, so the onset frame is the velocity frame whose interval holds the
    onset (:func:`slipkit.features.pins.onset_velocity_index`) and an alarm at sample
    ``s`` is at velocity frame ``s - 1``.
    """
    from slipkit.features.pins import onset_velocity_index

    onsets, firsts = [], []
    for k, (a, b) in enumerate(bounds):
        ts = t[a:b]
        onsets.append(
            onset_velocity_index(ts, float(onset_s[k])) if b - a >= 2 else None
        )
        first = _first(fired[a:b])
        firsts.append(None if first is None else first - 1)
    return trial_events(list(trial_ids), onsets, firsts)


# -- window classification ------------------------------------------------------------------


def adapt_windows(view: RunView) -> Evaluation:
    """Slip type / direction from windows (:class:`~slipkit.train.tasks.slip_type.WindowClassification`)."""
    m = view.metrics
    test = m["test"]
    labels = [str(x) for x in test["labels"]]
    cm = np.asarray(test["confusion"])
    row: dict[str, Any] = {
        "accuracy": float(test["accuracy"]),
        "balanced_accuracy": float(test["balanced_accuracy"]),
        "f1": float(test["f1_macro"]),
    }
    roc = None
    if len(labels) == 2:
        row.update(
            {
                k: v
                for k, v in binary_rates(cm).items()
                if k in ("tpr", "tnr", "fpr", "fnr")
            }
        )
        preds = pd.read_csv(view.folder / "test_predictions.csv")
        if "in_span" in preds:
            preds = preds[preds["in_span"].astype(bool)]
        column = f"p_{labels[1]}"
        if column in preds:
            roc = _roc(
                (preds["label"].astype(str) == labels[1]).to_numpy(),
                preds[column].to_numpy(float),
                (row["fpr"], row["tpr"]),
                f"windows ({labels[1]} positive)",
            )
            if roc is not None:
                row["roc_auc"] = roc["auc"]
    window = m["window"]
    row.update(
        window_frames=int(window["frames"]),
        window_ms=float(window["ms"]),
        decision_frames=int(window["frames"]),
    )
    row.update(_window_controls(m))
    vs_time = None
    path = view.folder / "accuracy_vs_time.csv"
    if path.is_file():
        curve = pd.read_csv(path)
        found = [c for c in ("accuracy_model", "model") if c in curve.columns]
        if found:
            vs_time = curve[["t_rel_s", found[0]]].rename(
                columns={found[0]: "accuracy"}
            )
    vs_width = None
    if m.get("accuracy_vs_width"):
        vs_width = pd.DataFrame(m["accuracy_vs_width"])[["ms", "accuracy"]]
    return Evaluation(
        row=row,
        confusion=(labels, cm),
        roc=roc,
        vs_time=vs_time,
        vs_width=vs_width,
        split=m["split"],
    )


def _window_controls(m: Mapping[str, Any]) -> dict[str, float]:
    """Per-sequence scores and the controls beside the headline (report's controls table).

    ``sequence_*``: majority vote of a trial's windows; ``first_frame_*``: the model
    fitted on each trial's first frame only; ``dynamics_*``: on windows minus the
    trial's first frame; ``majority_*``: the training side's most frequent class
    (window accuracy and balanced accuracy of each).
    """
    out: dict[str, float] = {}
    seq = m.get("sequence") or {}
    if seq:
        out["sequence_accuracy"] = float(seq["accuracy"])
        out["sequence_balanced_accuracy"] = float(seq["balanced_accuracy"])
    for name, c in (m.get("controls") or {}).items():
        win = c.get("window") or {}
        if win:
            out[f"{name}_accuracy"] = float(win["accuracy"])
            out[f"{name}_balanced_accuracy"] = float(win["balanced_accuracy"])
    return out


# -- stream detectors -----------------------------------------------------------------------


def adapt_detection(view: RunView) -> Evaluation:
    """Analytic stream detectors (:class:`~slipkit.train.tasks.detection.StreamDetection`)."""
    task: Any = view.task
    m = view.metrics
    test = m["test"]
    s = test["samples"]
    cm = np.array([[s["tn"], s["fp"]], [s["fn"], s["tp"]]])
    row: dict[str, Any] = binary_rates(cm)
    row["roc_auc"] = _num(s.get("auc"))
    trials = pd.read_csv(view.folder / "test_trials.csv")
    trials = trials[trials["detector"] == m["name"]] if "detector" in trials else trials
    latency = trials["delay_ms"].to_numpy(float)
    delays = [float(v) for v in latency if math.isfinite(v)]
    ev = test["events"]
    rec_rate = float(view.dataset.streams[task.stream].rate_hz or math.nan)
    point = dict(m.get("operating_point") or {})
    row.update(event_row(test["operating_point"], str(point.get("from", ""))))
    # event level (the papers' unit): one unit per slip, one per negative window
    row.update(
        event_tpr=_num(ev.get("tpr")),
        event_tnr=_num(ev.get("tnr")),
        event_auc=_num(ev.get("auc")),
    )
    window = _detector_window(view.model)
    row.update(
        window_frames=window,
        window_ms=window * 1000.0 / rec_rate,
        decision_frames=window,
    )
    roc = None
    test_ds = view.dataset.subset(list(m["split"]["test"]))
    rec = task.recordings(test_ds, task.stream, task.channels)
    scores = np.asarray(view.model.decision_function(rec.X, segments=rec.segments))
    roc = _roc(rec.y > 0, scores, (row["fpr"], row["tpr"]), "samples")
    event_table = None
    trial_measure = _TRIAL_EVENTS.get(str(view.dataset.sensor))
    if trial_measure is not None:  # the sensor family's own trial-event measure
        events, event_table = trial_measure(view, rec, scores, row)
        row.update(events)
    return Evaluation(
        row=row,
        confusion=(["no slip", "slip"], cm),
        roc=roc,
        delays_ms=delays,
        split=m["split"],
        trial_events=event_table,
    )


def _detector_window(model: Any) -> int:
    """Samples a detector reads before its first decision (its block / window / span)."""
    p = model.get_params()
    for key in ("window", "span"):
        if isinstance(p.get(key), int):
            return int(p[key])
    if isinstance(p.get("block"), int):
        return 2 * int(p["block"])  # a backward difference of two block means
    own = getattr(model, "window_samples", None)  # none of those: the detector says
    return own if isinstance(own, int) else 1


#: the trial-event columns a detection task's operating point gives a row
EVENT_COLUMNS = (
    "detected_rate",
    "early_alarm_rate",
    "false_alarms_per_min",
    "alarms_per_disturbance",
    "delay_ms",
    "delay_p90_ms",
    "missed",
    "n_slips",
    "event_trials",
    "disturbances",
    "cost",
)


def event_row(op: Mapping[str, Any], source: str) -> dict[str, Any]:
    """The row's trial-event columns from a task's test ``operating_point`` summary
    (:func:`slipkit.evaluate.events.summarise` with ``threshold`` and ``debounce_k``)
    and where the point was chosen (``operating_point_from``)."""
    row: dict[str, Any] = {c: _num(op.get(c)) for c in EVENT_COLUMNS}
    if not row["disturbances"]:
        row["disturbances"] = math.nan  # the data marks none
    row["threshold"] = _num(op.get("threshold"))
    row["debounce_k"] = _num(op.get("debounce_k"))
    row["operating_point_from"] = source
    row["unknown_onset_trials"] = _num(op.get("unknown_onset_trials"))
    row["cost_without_detector"] = _num(op.get("cost_without_detector"))
    return row


def _register_builtin() -> None:
    from slipkit.train.tasks.detection import StreamDetection
    from slipkit.train.tasks.slip_type import WindowClassification

    register_adapter(WindowClassification, adapt_windows)
    register_adapter(StreamDetection, adapt_detection)


_register_builtin()

__all__ = [
    "ON_TIME_FRAMES",
    "ROW_COLUMNS",
    "Evaluation",
    "RunView",
    "adapt",
    "binary_rates",
    "frame_task_events",
    "register_adapter",
    "register_trial_events",
    "stream_task_events",
    "trial_events",
]
