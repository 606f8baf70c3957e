"""Analytic stream detectors on simulated (or recorded) trials: ROC threshold, scores, latency.

:class:`StreamDetection` turns one stream of every trial into a detector's ``X`` (its
channels, in time order, one recording per trial, ``segments`` = trial) and per-sample
labels ``y``: a truth-stream column (``truth_column``, e.g. the FSR scene's
``slip_event``) or the onset label (``t >= slip_onset_s``). Trials are split in halves
(by trial, or by a group column with ``split: group``); ``fit`` chooses the operating
point on validation trials (below) and every side is scored:

* **samples** -- AUC and TPR/TNR/FPR/FNR per sample (the base detector's calibration);
* **events** -- as the FSR paper counts (30 induced slips, specificity over non-slip
  time): each labelled event (a run of slip samples) is one positive unit, detected if
  the detector fires within it (plus ``event_tolerance_s``); the non-slip time outside
  the events is cut into ``negative_window_s`` windows, each a negative unit that is a
  false positive if the detector fires in it. The unit score is the largest sample
  score, which gives an event ROC and AUC; ``roc_unit="event"`` chooses the threshold
  on it instead of on samples. Disturbances (a truth column) are counted apart: how many
  made the detector fire;
* **trials** -- a slip trial is a true positive if the detector fires during its slip
  (after the onset), and every trial's time before the onset is a negative that is a
  false positive if the detector fires there;
* **latency** -- first detection at or after the onset, in ms, per trial; with
  ``reference_label`` (the BioTac scene's IMU onset) the lead (-) or lag (+) against it,
  mean +- sd overall and per group (``group_by``), beside the paper's figures.
* **operating point** -- the threshold and debounce ``k`` the detector is deployed
  with, chosen on validation trials (``operating_point``): each detector's clones are
  fitted on ``cv`` - 1 folds of the training trials (group k-fold by the dataset's
  group column, e.g. ``object``, when it has one, else by trial) and score the
  held-out fold; on these out-of-fold scores every point of a grid (threshold
  quantiles plus each clone's own ROC choice, x the debounce candidates) is scored on
  the trial events of :mod:`slipkit.evaluate.events`, and the point of lowest mean
  cost within the limits (early alarms, alarms per disturbance) is kept. The detector
  is then fitted on all training trials with that threshold (a threshold fixed in its
  config stays; only ``k`` is chosen) and carries ``k`` as ``debounce_k_``; the test
  trials are scored once, there: slips detected, early alarms, false alarms per
  minute, alarms per disturbance, median and p90 delay, cost. ``metrics.json``
  records where the point came from (``operating_point``: the trials it was chosen
  on, never the test split's); ``slipkit train`` and ``slipkit evaluate`` print it
  first.

``compare`` adds detectors scored the same way beside the run's estimator, each on its
own stream (the BioTac pressure detector reads ``pac`` at 2.2 kHz, the force derivative
``truth_force`` at 300 Hz). They are fitted on the same training trials; ``evaluate``
can score only those with a fixed ``threshold`` (the run saves the estimator alone).
Detectors are causal, so cutting a recording at the end of its scored part
(``score_until``: the last sample of a truth column, e.g. the FSR pass before the probe
leaves the sensor) changes no score before it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from hydra.utils import instantiate
from numpy.typing import NDArray
from sklearn.base import clone
from sklearn.metrics import roc_curve

from slipkit.baselines.base import StreamDetector as _StreamDetector
from slipkit.data.dataset import Dataset
from slipkit.data.splits import TrialSplit, split_by_group, split_by_trial
from slipkit.errors import SlipkitError
from slipkit.evaluate.events import (
    Cost,
    Limits,
    OperatingPoint,
    TrialTruth,
    choose_operating_point,
    evaluate_point,
    events_table,
    parse_operating_point,
    slipped_of,
    threshold_grid,
)
from slipkit.train.search import mean_leaves
from slipkit.train.task import Task, TaskResult
from slipkit.train.tasks.detection_data import (
    Recordings,
    _auc,
    _mean_sd,
    _rates,
    _roc_choice,
    _runs,
)
from slipkit.train.tasks.detection_report import (
    _direction,
    _plain,
    _plot_roc,
    _summary_block,
    operating_point_line,
)

log = logging.getLogger("slipkit.detection")
FloatArray = NDArray[np.float64]


class StreamDetection(Task):
    """Fit and score a :class:`~slipkit.baselines.base.StreamDetector` on trials.

    Parameters
    ----------
    stream : str
        The stream the estimator reads.
    channels : list of str or None
        Its channels, in order (None: all of them).
    label : str or None
        Onset label (s): the slip onset of every trial (latency is measured from it);
        samples at or after it are slip unless ``truth_column`` is set.
    truth_stream, truth_column : str or None
        Per-sample slip labels from a truth column (non-zero = slip), looked up at each
        sample's time (latest truth row at or before it).
    score_until : str or None
        A truth column: each trial is scored up to its last non-zero sample (None: all).
    disturbance_column : str or None
        A truth column marking disturbances (counted: did the detector fire in one?).
    roc_unit : {"sample", "event"}
        The ROC a free threshold is chosen on (see the module docstring).
    negative_window_s : float
        Length of a negative unit of the event counts (s).
    event_tolerance_s : float
        A detection up to this long after an event still counts for it (s).
    reference_label : str or None
        A second onset (the IMU's) to report the detection lead / lag against.
    group_by : str or None
        Trial group column (e.g. ``object``) for per-group latency.
    test_size : float
        Fraction of trials held out for the test side.
    split : {"trial", "group", "auto"}
        The test split: by trial, by ``group`` (every group on one side), or by group
        when the dataset has the group column with two values or more, else by trial.
    group : str or None
        The trials column naming a trial's group (e.g. ``object``) for ``split`` and
        for the validation folds; None: ``object`` when the dataset has it.
    stratify : str or None
        A by-trial split keeps the shares of this trials column (e.g. ``material``)
        when every value has two trials or more, else splits plainly (as the SlipTack
        speed task, so a comparison's detectors share its split); None: plainly.
    operating_point : mapping or None
        How the deployed (threshold, debounce) is chosen on validation trials:
        ``debounce`` (candidate k), ``thresholds`` (quantiles of the out-of-fold
        scores), ``cost`` (``{miss, early_alarm, delay_ms}``), ``max_early_alarm_rate``,
        ``max_alarms_per_disturbance`` (:mod:`slipkit.evaluate.events`); None: the
        detector's own threshold (its ROC or config) with debounce 1.
    name, unit : str
        How the summary names the estimator and its threshold's unit.
    paper : mapping or None
        Published figures printed beside the measured ones: ``threshold``, ``auc``,
        ``tpr``, ``tnr`` (fractions), ``reference_ms`` ({group: [mean, sd]}).
    compare : list of mappings or None
        Further detectors: ``{name, detector, stream, channels, unit, paper}``
        (``detector`` an estimator or a ``_target_`` mapping).
    objective : str
        Metrics key returned to a sweeper (dots descend): a ``validation.*`` key, the
        main detector refitted by ``cv``-fold group CV on the training side and scored
        on the held-out fold (mean over folds; ``validation.operating_point.*``: the
        chosen point on the pooled out-of-fold scores), never the test side. A cost,
        delay or rate is minimised, anything else maximised.
    cv : int
        Folds of that validation (fewer when the training side has fewer groups).
    """

    accepts = (_StreamDetector,)
    refuses = ()
    feeds = "runs an analytic stream detector (StreamDetector) on stream {stream}"

    objective = "validation.samples.auc"
    direction = "maximize"

    def __init__(
        self,
        *,
        stream: str,
        channels: Sequence[str] | None = None,
        label: str | None = "slip_onset_s",
        truth_stream: str | None = None,
        truth_column: str | None = None,
        score_until: str | None = None,
        disturbance_column: str | None = None,
        roc_unit: str = "sample",
        negative_window_s: float = 0.01,
        event_tolerance_s: float = 0.0,
        reference_label: str | None = None,
        group_by: str | None = None,
        test_size: float = 0.5,
        split: str = "trial",
        group: str | None = None,
        stratify: str | None = None,
        operating_point: Mapping[str, Any] | None = None,
        name: str = "detector",
        unit: str = "",
        paper: Mapping[str, Any] | None = None,
        compare: Sequence[Mapping[str, Any]] | None = None,
        objective: str = "validation.samples.auc",
        cv: int = 3,
    ) -> None:
        if roc_unit not in ("sample", "event"):
            raise SlipkitError(
                f"task.roc_unit must be 'sample' or 'event'; got {roc_unit!r}"
            )
        if split not in ("trial", "group", "auto"):
            raise SlipkitError(
                f"task.split must be 'trial', 'group' or 'auto'; got {split!r}"
            )
        if (truth_column is None) != (truth_stream is None):
            raise SlipkitError("task.truth_stream and task.truth_column go together")
        if truth_column is None and label is None:
            raise SlipkitError("task: set label (onset) or truth_stream + truth_column")
        self.stream = stream
        self.channels = None if channels is None else [str(c) for c in channels]
        self.label = label
        self.truth_stream = truth_stream
        self.truth_column = truth_column
        self.score_until = score_until
        self.disturbance_column = disturbance_column
        self.roc_unit = roc_unit
        self.negative_window_s = float(negative_window_s)
        self.event_tolerance_s = float(event_tolerance_s)
        self.reference_label = reference_label
        self.group_by = group_by
        self.test_size = float(test_size)
        self.split = split
        self.group = group
        self.stratify = stratify
        self.operating_point = parse_operating_point(operating_point)
        self.name = name
        self.unit = unit
        self.paper = dict(paper or {})
        self.compare = [dict(c) for c in (compare or [])]
        self.objective = objective
        self.direction = _direction(objective)
        self.cv = cv

    # -- data -------------------------------------------------------------------------
    def _truth(self, trial: Any, column: str) -> tuple[FloatArray, FloatArray]:
        if self.truth_stream is None:
            raise SlipkitError(f"task: {column!r} needs task.truth_stream")
        df = trial.streams.get(self.truth_stream)
        if df is None or column not in df:
            raise SlipkitError(
                f"trial {trial.trial_id}: truth stream {self.truth_stream!r} has no "
                f"column {column!r}"
            )
        if not len(df):
            raise SlipkitError(
                f"trial {trial.trial_id}: truth stream {self.truth_stream!r} is empty"
            )
        return df["t"].to_numpy(np.float64), df[column].to_numpy(np.float64)

    def _at(self, t_truth: FloatArray, v: FloatArray, t: FloatArray) -> FloatArray:
        # latest truth row at or before each sample (truth and stream may differ in rate)
        k = np.clip(np.searchsorted(t_truth, t, side="right") - 1, 0, len(v) - 1)
        return v[k]

    def recordings(
        self, dataset: Dataset, stream: str, channels: Sequence[str] | None
    ) -> Recordings:
        """``X``, ``y``, times and per-trial facts of ``stream`` over ``dataset``."""
        if stream not in dataset.streams:
            raise SlipkitError(
                f"dataset {dataset.name!r} has no stream {stream!r}; streams: "
                f"{sorted(dataset.streams)}"
            )
        spec = dataset.streams[stream]
        chans = list(channels) if channels is not None else list(spec.channels)
        Xs, ys, ts, segs, dists = [], [], [], [], []
        ids, groups, onsets, refs = [], [], [], []
        slipped: list[bool | None] = []
        for k, trial in enumerate(dataset):
            df = trial.streams.get(stream)
            if df is None:
                raise SlipkitError(f"trial {trial.trial_id}: no stream {stream!r}")
            missing = [c for c in chans if c not in df]
            if missing:
                raise SlipkitError(
                    f"trial {trial.trial_id}: stream {stream!r} has no channel(s) "
                    f"{missing}; it has {[c for c in df.columns if c != 't']}"
                )
            t = df["t"].to_numpy(np.float64)
            onset = (
                float(trial.labels.get(self.label, np.nan)) if self.label else np.nan
            )
            if self.truth_column is not None:
                tt, v = self._truth(trial, self.truth_column)
                y = self._at(tt, v, t) > 0
                if self.label is None and y.any():
                    onset = float(t[np.argmax(y)])
            else:
                y = t >= onset if math.isfinite(onset) else np.zeros(len(t), bool)
            keep = len(t)
            if self.score_until is not None:
                tt, v = self._truth(trial, self.score_until)
                on = np.flatnonzero(v > 0)
                if len(on):
                    keep = int(np.searchsorted(t, tt[on[-1]], side="right"))
            if keep == 0:
                raise SlipkitError(
                    f"trial {trial.trial_id}: stream {stream!r} has no samples to score"
                )
            dist = None
            if self.disturbance_column is not None:
                tt, v = self._truth(trial, self.disturbance_column)
                dist = self._at(tt, v, t)[:keep] > 0
                dists.append(dist)
            Xs.append(df[chans].to_numpy(np.float64)[:keep])
            ys.append(y[:keep].astype(int))
            ts.append(t[:keep])
            segs.append(np.full(keep, k))
            ids.append(trial.trial_id)
            groups.append(
                str(trial.meta.get(self.group_by, "")) if self.group_by else ""
            )
            onsets.append(onset)
            slipped.append(
                bool(y[:keep].any())
                if self.truth_column is not None
                else slipped_of(trial.labels, onset)
            )
            ref = (
                float(trial.labels.get(self.reference_label, np.nan))
                if self.reference_label
                else np.nan
            )
            refs.append(ref)
        if not Xs:
            raise SlipkitError(f"dataset {dataset.name!r} holds no trials")
        rate = spec.rate_hz
        if rate is None:
            dt = np.median(np.diff(ts[0])) if len(ts[0]) > 1 else np.nan
            rate = 1.0 / dt if np.isfinite(dt) and dt > 0 else 1.0
        return Recordings(
            X=np.concatenate(Xs),
            y=np.concatenate(ys),
            t=np.concatenate(ts),
            segments=np.concatenate(segs),
            trial_ids=ids,
            groups=groups,
            onset_s=np.asarray(onsets, dtype=np.float64),
            reference_s=np.asarray(refs, dtype=np.float64),
            disturbance=np.concatenate(dists) if dists else None,
            rate_hz=float(rate),
            slipped=slipped,
        )

    # -- event units --------------------------------------------------------------------
    def event_units(
        self, rec: Recordings, scores: FloatArray
    ) -> tuple[NDArray[np.int_], FloatArray, NDArray[np.int_]]:
        """(label, max score, trial index) of every event unit (see the module doc)."""
        tol = round(self.event_tolerance_s * rec.rate_hz)
        width = max(1, round(self.negative_window_s * rec.rate_hz))
        labels: list[int] = []
        best: list[float] = []
        trial: list[int] = []
        for k, (a, b) in enumerate(rec.bounds()):
            y = rec.y[a:b] > 0
            s = scores[a:b]
            covered = np.zeros(b - a, dtype=bool)
            for r0, r1 in _runs(y):
                hi = min(b - a, r1 + tol)
                labels.append(1)
                best.append(float(s[r0:hi].max()))
                trial.append(k)
                covered[r0:hi] = True
            for g0, g1 in _runs(~covered):
                for w0 in range(g0, g1, width):
                    labels.append(0)
                    best.append(float(s[w0 : min(g1, w0 + width)].max()))
                    trial.append(k)
        return (
            np.asarray(labels, dtype=int),
            np.asarray(best, dtype=np.float64),
            np.asarray(trial, dtype=int),
        )

    # -- scoring --------------------------------------------------------------------------
    def score(
        self,
        detector: Any,
        rec: Recordings,
        *,
        extra_thresholds: Mapping[str, float] | None = None,
        debounce_k: int | None = None,
    ) -> tuple[dict[str, Any], pd.DataFrame, dict[str, Any]]:
        """Metrics, the per-trial events table and the ROC curves of a fitted detector.

        The trial events (``operating_point``, the table) are at the detector's
        threshold with ``debounce_k`` (None: the detector's ``debounce_k_``, else 1);
        the per-sample, event-unit and trial counts at its threshold sample by sample.
        """
        scores = np.asarray(detector.decision_function(rec.X, segments=rec.segments))
        thr = float(detector.threshold_)
        k = int(
            debounce_k
            if debounce_k is not None
            else getattr(detector, "debounce_k_", 1)
        )
        metrics = self._at_threshold(rec, scores, thr, debounce_k=k)
        metrics["threshold"] = thr
        for key, value in (extra_thresholds or {}).items():
            metrics[key] = {
                "threshold": float(value),
                **self._at_threshold(rec, scores, float(value), brief=True),
            }
        _, events = evaluate_point(
            rec.truths(),
            rec.per_trial(scores),
            thr,
            k,
            self.cost,
            tolerance_s=self.event_tolerance_s,
        )
        table = events_table(events, self.cost)
        table.insert(1, "group", rec.groups)
        low = np.finfo(np.float64).min
        curves: dict[str, Any] = {}
        if len(np.unique(rec.y)) == 2:
            fpr, tpr, _ = roc_curve(rec.y, np.where(np.isfinite(scores), scores, low))
            curves["samples"] = (fpr, tpr)
        ev_y, ev_s, _ = self.event_units(rec, scores)
        if len(np.unique(ev_y)) == 2:
            fpr, tpr, _ = roc_curve(ev_y, np.where(np.isfinite(ev_s), ev_s, low))
            curves["events"] = (fpr, tpr)
        return metrics, table, curves

    def _at_threshold(
        self,
        rec: Recordings,
        scores: FloatArray,
        thr: float,
        *,
        brief: bool = False,
        debounce_k: int = 1,
    ) -> dict[str, Any]:
        pred = scores >= thr
        samples = {
            "auc": _auc(rec.y, scores),
            "n_pos": int((rec.y == 1).sum()),
            "n_neg": int((rec.y == 0).sum()),
            **_rates(rec.y, pred),
        }
        ev_y, ev_s, _ = self.event_units(rec, scores)
        events = {
            "auc": _auc(ev_y, ev_s),
            "n_events": int((ev_y == 1).sum()),
            "n_negative_windows": int((ev_y == 0).sum()),
            **_rates(ev_y, ev_s >= thr),
        }
        events["sensitivity"], events["specificity"] = events["tpr"], events["tnr"]
        out: dict[str, Any] = {"samples": samples, "events": events}
        if rec.disturbance is not None:
            runs = [
                (a + r0, a + r1)
                for a, b in rec.bounds()
                for r0, r1 in _runs(rec.disturbance[a:b])
            ]
            fired = sum(bool(pred[r0:r1].any()) for r0, r1 in runs)
            out["disturbances"] = {"n": len(runs), "fired": int(fired)}
        if brief:
            return out
        trials = self._trial_table(rec, pred)
        slip = trials["onset_s"].notna()
        out["trials"] = {
            "n": len(trials),
            "n_slip": int(slip.sum()),
            **_rates(
                np.concatenate(
                    [np.ones(int(slip.sum()), int), np.zeros(len(trials), int)]
                ),
                np.concatenate(
                    [
                        trials.loc[slip, "detected"].to_numpy(bool),
                        trials["fired_before"].to_numpy(bool),
                    ]
                ),
            ),
        }
        out["latency_ms"] = _mean_sd(trials["latency_ms"].tolist())
        summary, _ = evaluate_point(
            rec.truths(),
            rec.per_trial(scores),
            thr,
            debounce_k,
            self.cost,
            tolerance_s=self.event_tolerance_s,
        )
        out["operating_point"] = {
            "threshold": thr,
            "debounce_k": int(debounce_k),
            **summary,
        }
        if rec.reference_s is not None and np.isfinite(rec.reference_s).any():
            ref: dict[str, Any] = {"all": _mean_sd(trials["vs_reference_ms"].tolist())}
            if self.group_by:
                for g, part in trials.groupby("group", sort=True):
                    ref[str(g)] = _mean_sd(part["vs_reference_ms"].tolist())
            out["vs_reference_ms"] = ref
        return out

    def _trial_table(self, rec: Recordings, pred: NDArray[np.bool_]) -> pd.DataFrame:
        rows = []
        for k, (a, b) in enumerate(rec.bounds()):
            t, p, y = rec.t[a:b], pred[a:b], rec.y[a:b] > 0
            onset = rec.onset_s[k]
            has_slip = math.isfinite(onset) and y.any()
            before = p & (t < onset) if math.isfinite(onset) else p
            after = np.flatnonzero(p & (t >= onset)) if has_slip else np.empty(0, int)
            # detected: fires while a slip sample is labelled (or within the tolerance)
            tol = self.event_tolerance_s
            during = False
            if has_slip:
                for r0, r1 in _runs(y):
                    stop = np.searchsorted(t, t[r1 - 1] + tol, side="right")
                    during = during or bool(p[r0:stop].any())
            first = float(t[after[0]]) if len(after) else float("nan")
            rows.append(
                {
                    "trial_id": rec.trial_ids[k],
                    "group": rec.groups[k],
                    "onset_s": onset if has_slip else float("nan"),
                    "first_detection_s": first,
                    "latency_ms": (first - onset) * 1000.0
                    if has_slip
                    else float("nan"),
                    "vs_reference_ms": (first - rec.reference_s[k]) * 1000.0,
                    "fired_before": bool(before.any()),
                    "detected": during,
                }
            )
        return pd.DataFrame(rows)

    # -- fit / evaluate ---------------------------------------------------------------------
    def _entries(self, model: Any) -> list[dict[str, Any]]:
        main = {
            "name": self.name,
            "detector": model,
            "stream": self.stream,
            "channels": self.channels,
            "unit": self.unit,
            "paper": self.paper,
        }
        out = [main]
        for c in self.compare:
            det = c.get("detector")
            if isinstance(det, Mapping):
                det = instantiate(dict(det))
            if det is None:
                raise SlipkitError(
                    f"task.compare entry {c.get('name')!r} has no detector"
                )
            out.append(
                {
                    "name": str(c.get("name", type(det).__name__)),
                    "detector": clone(det),
                    "stream": str(c["stream"]),
                    "channels": c.get("channels"),
                    "unit": str(c.get("unit", "")),
                    "paper": dict(c.get("paper") or {}),
                }
            )
        return out

    def _fit_one(self, det: Any, rec: Recordings) -> dict[str, Any]:
        """Fit ``det`` on ``rec``; with ``roc_unit="event"`` choose on the event ROC."""
        if self.roc_unit == "event" and det.get_params().get("threshold") is None:
            # A provisional per-sample choice gives the scores; the event ROC then
            # fixes the threshold and a second fit records the per-sample ROC at it.
            det.fit(rec.X, rec.y, segments=rec.segments)
            scores = det.decision_function(rec.X, segments=rec.segments)
            ev_y, ev_s, _ = self.event_units(rec, scores)
            if len(np.unique(ev_y)) < 2:
                raise SlipkitError(
                    "the event ROC needs slip events and non-slip time in the training "
                    "trials"
                )
            chosen = _roc_choice(ev_y, ev_s, det.get_params()["roc_point"])
            det.set_params(threshold=chosen)
            det.fit(rec.X, rec.y, segments=rec.segments)
            return {
                "threshold_from": "event ROC (Youden)"
                if det.roc_point == "youden"
                else "event ROC (closest)"
            }
        det.fit(rec.X, rec.y, segments=rec.segments)
        fixed = det.get_params().get("threshold") is not None
        return {"threshold_from": "fixed (config)" if fixed else "sample ROC"}

    # -- operating point ------------------------------------------------------------------
    @property
    def cost(self) -> Cost:
        """The cost weights of the trial events (``operating_point.cost``)."""
        return (self.operating_point or {}).get("cost") or Cost()

    @property
    def limits(self) -> Limits:
        """The limits an operating point is chosen within (``operating_point``)."""
        return (self.operating_point or {}).get("limits") or Limits()

    def _group_column(self, dataset: Dataset) -> str | None:
        """The trials column of the groups (``group``, else ``object``), if the data has it."""
        name = self.group or "object"
        return name if name in dataset.trials.columns else None

    def split_of(self, dataset: Dataset, seed: int) -> tuple[TrialSplit, str]:
        """The test split (``split``) and what it splits by (``trial`` or the group column)."""
        col = self._group_column(dataset)
        by_group = self.split == "group" or (
            self.split == "auto"
            and col is not None
            and dataset.trials[col].astype(str).nunique() >= 2
        )
        if by_group:
            if col is None:
                raise SlipkitError(
                    f"task.split=group: dataset {dataset.name!r} has no trial group "
                    f"{self.group or 'object'!r} (task.group); its trials columns: "
                    f"{sorted(dataset.trials.columns)}"
                )
            split = split_by_group(
                dataset, col, test_size=self.test_size, val_size=0.0, seed=seed
            )
            return split, col
        if self.stratify is not None:
            try:
                split = split_by_trial(
                    dataset,
                    test_size=self.test_size,
                    seed=seed,
                    stratify=self.stratify,
                )
                return split, "trial"
            except (ValueError, KeyError):
                pass  # too few trials of a value (or no such column): a plain split
        split = split_by_trial(
            dataset, test_size=self.test_size, val_size=0.0, seed=seed
        )
        return split, "trial"

    def _cv_groups(self, train: Dataset) -> tuple[NDArray[Any], str]:
        """The validation folds' groups: the group column when the training side has
        two groups or more, else the trial ids."""
        col = self._group_column(train)
        ids = np.asarray(train.trial_ids, dtype=object)
        if col is not None:
            groups = train.trials.set_index("trial_id").loc[ids, col].astype(str)
            if groups.nunique() >= 2:
                return groups.to_numpy(dtype=object), col
        return ids, "trial"

    def _choose(
        self,
        detector: Any,
        truths: Sequence[TrialTruth],
        scores: Sequence[FloatArray],
        own: Sequence[float],
    ) -> OperatingPoint | None:
        """The operating point on these (validation) trials; None without
        ``operating_point``. A threshold fixed in the detector's config stays."""
        cfg = self.operating_point
        if cfg is None:
            return None
        fixed = detector.get_params().get("threshold")
        thresholds = (
            np.asarray([float(fixed)])
            if fixed is not None
            else threshold_grid(scores, int(cfg["thresholds"]), extra=own)
        )
        return choose_operating_point(
            truths,
            scores,
            thresholds=thresholds,
            debounce_ks=cfg["debounce"],
            cost=self.cost,
            limits=self.limits,
            tolerance_s=self.event_tolerance_s,
        )

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        split, split_by = self.split_of(dataset, seed)
        train, _, test = split.apply(dataset)
        metrics: dict[str, Any] = {
            "split": {"train": list(split.train), "test": list(split.test)},
            "split_by": split_by,
            "detectors": {},
        }
        curves: dict[str, Any] = {}
        tables = []
        for i, e in enumerate(self._entries(model)):
            validation, point, source = self.validation(e, train)
            if i == 0:
                metrics["validation"] = validation
            rec_tr = self.recordings(train, e["stream"], e["channels"])
            rec_te = self.recordings(test, e["stream"], e["channels"])
            det = e["detector"]
            if point is not None and det.get_params().get("threshold") is None:
                # the point chosen on validation trials; the fit keeps its threshold
                det.set_params(threshold=point.threshold)
                det.fit(rec_tr.X, rec_tr.y, segments=rec_tr.segments)
                info = {"threshold_from": f"lowest cost on {source}"}
            else:
                info = self._fit_one(det, rec_tr)
            det.debounce_k_ = point.debounce_k if point is not None else 1
            chosen = (
                {
                    **point.record(source),
                    # what is deployed: a detector may move a threshold that sits on
                    # a training score (FSRTouchSlip) when it fits
                    "threshold": float(det.threshold_),
                    "validation_threshold": float(point.threshold),
                }
                if point is not None
                else {
                    "threshold": float(det.threshold_),
                    "debounce_k": 1,
                    "from": info["threshold_from"] + ", debounce 1",
                }
            )
            extra = (
                {"at_paper_threshold": float(e["paper"]["threshold"])}
                if "threshold" in e["paper"]
                and float(e["paper"]["threshold"]) != float(det.threshold_)
                else None
            )
            m_tr, _, _ = self.score(det, rec_tr)
            # the test side, scored once at the chosen point
            m_te, table, cv = self.score(det, rec_te, extra_thresholds=extra)
            block = {
                "estimator": type(det).__name__,
                "stream": e["stream"],
                "unit": e["unit"],
                "threshold": float(det.threshold_),
                **info,
                "operating_point": chosen,
                "params": {k: _plain(v) for k, v in det.get_params().items()},
                "train": m_tr,
                "test": m_te,
                "paper": e["paper"],
            }
            if i == 0:
                metrics.update({"name": e["name"], **block})
                model = det
            else:
                metrics["detectors"][e["name"]] = block
            curves[e["name"]] = cv
            tables.append(table.assign(detector=e["name"]))
        pd.concat(tables).to_csv(out / "test_trials.csv", index=False)
        _plot_roc(curves, out / "roc.png")
        return TaskResult(model, metrics, self.summary(metrics))

    def validation(
        self, entry: Mapping[str, Any], train: Dataset
    ) -> tuple[dict[str, Any], OperatingPoint | None, str]:
        """Group CV on the training side and the operating point chosen on it.

        Clones of the entry's detector are fitted (threshold chosen as configured) on
        k-1 folds and scored on the held-out fold; every numeric metric is averaged
        over the folds (NaN-aware), and the operating point (:meth:`_choose`) is chosen
        on the pooled out-of-fold scores of every training trial
        (``operating_point`` holds its trial-event summary there). Folds are groups of
        the group column when the training side has two or more, else trials.

        Returns
        -------
        (validation metrics, operating point or None, where it was chosen)
        """
        from sklearn.model_selection import GroupKFold

        ids = np.asarray(train.trial_ids, dtype=object)
        groups, by = self._cv_groups(train)
        k = min(int(self.cv), len(set(groups)))
        if k < 2:
            # No CV with one training trial: the clone is scored on the trial it was
            # fitted on (AUCs do not depend on the threshold chosen there; the rest
            # and the operating point are optimistic).
            log.warning("validation: %d training trial(s), no group CV", len(ids))
            det = clone(entry["detector"])
            rec = self.recordings(train, entry["stream"], entry["channels"])
            self._fit_one(det, rec)
            m, _, _ = self.score(det, rec, debounce_k=1)
            s = np.asarray(det.decision_function(rec.X, segments=rec.segments))
            point = self._choose(
                det, rec.truths(), rec.per_trial(s), [float(det.threshold_)]
            )
            out = {
                "cv": f"none: {len(ids)} training trial(s), scored on the training "
                "side (AUCs ignore the threshold fitted there; the rest is optimistic)",
                "k": 0,
                **m,
            }
            if point is not None:
                out["operating_point"] = point.summary
            return out, point, f"the {len(ids)} training trial(s) (no CV: optimistic)"
        folds = []
        truths: list[TrialTruth] = []
        scores: list[FloatArray] = []
        own: list[float] = []
        for j, (a, b) in enumerate(GroupKFold(n_splits=k).split(ids, groups=groups)):
            det = clone(entry["detector"])
            rec_a = self.recordings(
                train.subset(ids[a]), entry["stream"], entry["channels"]
            )
            rec_b = self.recordings(
                train.subset(ids[b]), entry["stream"], entry["channels"]
            )
            self._fit_one(det, rec_a)
            folds.append(self.score(det, rec_b, debounce_k=1)[0])
            s = np.asarray(det.decision_function(rec_b.X, segments=rec_b.segments))
            truths += rec_b.truths()
            scores += rec_b.per_trial(s)
            own.append(float(det.threshold_))
            log.info("validation fold %d/%d done", j + 1, k)
        out = {"cv": f"group-kfold by {by}", "k": k, **mean_leaves(folds)}
        point = self._choose(entry["detector"], truths, scores, own)
        if point is not None:
            out["operating_point"] = point.summary
        return out, point, f"validation: group k-fold by {by}, k={k}"

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        metrics: dict[str, Any] = {"detectors": {}}
        curves: dict[str, Any] = {}
        tables = []
        for i, e in enumerate(self._entries(model)):
            rec = self.recordings(dataset, e["stream"], e["channels"])
            det = e["detector"]
            if i > 0:
                if det.get_params().get("threshold") is None:
                    metrics["detectors"][e["name"]] = {
                        "skipped": "its ROC-chosen threshold is not saved in the run; "
                        "give it a fixed threshold to evaluate it"
                    }
                    continue
                det.fit(
                    rec.X, rec.y, segments=rec.segments
                )  # fixed: records the ROC only
            m, table, cv = self.score(det, rec)
            block = {
                "estimator": type(det).__name__,
                "unit": e["unit"],
                "test": m,
                "paper": e["paper"],
            }
            if i == 0:
                metrics.update({"name": e["name"], **block})
            else:
                metrics["detectors"][e["name"]] = block
            curves[e["name"]] = cv
            tables.append(table.assign(detector=e["name"]))
        pd.concat(tables).to_csv(out / "trials.csv", index=False)
        _plot_roc(curves, out / "roc.png")
        return metrics

    # -- report ------------------------------------------------------------------------------
    def headline(self, metrics: Mapping[str, Any]) -> list[str]:
        """The main detector's operating point on the test side (printed first)."""
        test = metrics.get("test") or {}
        if "operating_point" not in test:
            return []
        return [operating_point_line(metrics["name"], test, metrics.get("unit", ""))]

    def summary(self, metrics: Mapping[str, Any]) -> list[str]:
        """Lines printed after training: the operating point on the test trials, then
        each detector beside the paper's figures."""
        lines = self.headline(metrics)
        blocks = [(metrics["name"], metrics), *metrics["detectors"].items()]
        for name, b in blocks:
            lines.extend(_summary_block(name, b, self.group_by))
        return lines


__all__ = ["Recordings", "StreamDetection", "operating_point_line"]
