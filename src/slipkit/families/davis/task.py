"""DAVIS incipient slip detection scored as Rigi et al. 2018 do (Sensors 18(2):333, Sec. 4.4).

Each trial's events run through the detector in 10 ms frames; time is split in 20 ms
bins; a bin is truth-positive when it overlaps the slip interval (from the incipient-slip
onset label, Sec. 4.3, to the first ground-truth frame with no contact); TP / FP / FN are
counted per bin (TN ignored), precision, sensitivity and F1 follow (eqs. 1-3), and the
latency is the time from the onset to the first true-positive detection. Like the paper's
Table 1, the headline is the mean over trials (experiments); pooled counts are reported too.
Beside the bins, the trial events of every detection comparison
(:mod:`slipkit.evaluate.events`, ``test.operating_point``): an alarm at the ``k``-th
consecutive frame the detector declares slip, against the onset. The debounce ``k`` is
chosen on the training trials (``operating_point``: the candidates, the cost and its
limits) and the test trials are scored once at it. A rule has nothing to learn, so
``fit`` only checks it on the training trials and every number comes from the held-out
ones.
"""

from __future__ import annotations

import inspect
import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from slipkit.data.dataset import Dataset, Trial
from slipkit.data.splits import split_by_trial
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
)
from slipkit.families.davis.classifier import (
    EventFrameClassifier as _EventFrameClassifier,
)
from slipkit.families.davis.polarity import DavisPolarity as _DavisPolarity
from slipkit.families.davis.polarity import bin_scores, contact_end, prf
from slipkit.train.task import Task, TaskResult, register_analytic_estimator

log = logging.getLogger("slipkit.davis")

#: Rigi et al. 2018, Table 1 (average over 37 experiments, 5 objects)
PAPER = {
    "precision": 0.70,
    "sensitivity": 0.85,
    "f1": 0.75,
    "latency_ms": 44.1,
    "latency_sd_ms": 45.5,
}


class DavisRelease(Task):
    """Per-bin slip scoring of an event detector on ``davis_release`` trials.

    Parameters
    ----------
    bin_s : float
        Scoring bin (s; the paper: 0.02).
    test_size : float
        Fraction of trials held out.
    stream : str
        Event stream (``t, x, y, polarity``).
    truth_stream, area_column : str
        Ground-truth contact area per frame (slip ends when it reaches 0).
    label : str
        Incipient slip onset (s).
    group : str
        Group column for the per-object breakdown.
    operating_point : mapping or None
        How the deployed debounce is chosen on the training trials: ``debounce``
        (candidate k: an alarm at the k-th consecutive slip frame), ``cost``
        (``{miss, early_alarm, delay_ms}``), ``max_early_alarm_rate``,
        ``max_alarms_per_disturbance`` (:mod:`slipkit.evaluate.events`; ``thresholds``
        is not used: the detector's own per-frame decision is the score); None:
        debounce 1 (the detector's decision on one frame), default cost.

    The objective, ``validation.mean.f1``, is the F1 on the training trials: the
    detector's rule is fixed (``fit`` only checks parameters and events, nothing is
    learned from the labels), so the training trials are as unseen as a CV fold would
    be, and a sweep over its parameters never reads the test half.
    """

    accepts = (_DavisPolarity, _EventFrameClassifier)
    refuses = ()
    feeds = "runs a DAVIS event-frame detector (the polarity rule or a learned one)"

    objective = "validation.mean.f1"
    direction = "maximize"

    def __init__(
        self,
        *,
        bin_s: float = 0.02,
        test_size: float = 0.5,
        stream: str = "events",
        truth_stream: str = "truth_contact",
        area_column: str = "area_px",
        label: str = "slip_onset_s",
        group: str = "object",
        operating_point: Mapping[str, Any] | None = None,
    ) -> None:
        self.bin_s = bin_s
        self.test_size = test_size
        self.stream = stream
        self.truth_stream = truth_stream
        self.area_column = area_column
        self.label = label
        self.group = group
        self.operating_point = parse_operating_point(operating_point)

    @property
    def cost(self) -> Cost:
        """The cost weights of the trial events (``operating_point.cost``)."""
        return (self.operating_point or {}).get("cost") or Cost()

    @property
    def limits(self) -> Limits:
        """The limits the debounce is chosen within (``operating_point``)."""
        return (self.operating_point or {}).get("limits") or Limits()

    def _events(self, trial: Trial) -> pd.DataFrame:
        if self.stream not in trial.streams:
            raise SlipkitError(
                f"trial {trial.trial_id}: no event stream {self.stream!r} "
                f"(has {sorted(trial.streams)})"
            )
        return trial.streams[self.stream]

    def _events_xy(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
        tables, segs = [], []
        for i, trial in enumerate(dataset):
            ev = self._events(trial)[["t", "x", "y", "polarity"]].to_numpy(np.float64)
            tables.append(ev)
            segs.append(np.full(len(ev), i))
        if not tables:
            return np.empty((0, 4)), np.empty(0, dtype=int)
        return np.concatenate(tables), np.concatenate(segs)

    def _truth_spans(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
        """Slip onset and end of contact (s) of every trial, as scored (``inf``: no slip)."""
        onsets, ends = [], []
        for trial in dataset:
            onset = float(trial.labels.get(self.label, np.inf))
            truth = trial.streams.get(self.truth_stream)
            if not np.isfinite(onset) or truth is None:
                onsets.append(np.inf)
                ends.append(np.inf)
                continue
            onsets.append(onset)
            ends.append(
                contact_end(
                    truth["t"].to_numpy(), truth[self.area_column].to_numpy(), onset
                )
            )
        return np.asarray(onsets), np.asarray(ends)

    def trial_table(
        self, model: Any, dataset: Dataset
    ) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Per-trial TP / FP / FN / latency, and every frame of every trial."""
        rows, frames = [], []
        for trial in dataset:
            frames_t = model.frames(self._events(trial))
            truth = trial.streams.get(self.truth_stream)
            if truth is None or self.area_column not in truth.columns:
                raise SlipkitError(
                    f"trial {trial.trial_id}: needs {self.truth_stream!r} with column "
                    f"{self.area_column!r} (the ground-truth contact area)"
                )
            if self.label not in trial.labels:
                raise SlipkitError(f"trial {trial.trial_id}: no label {self.label!r}")
            onset = float(trial.labels[self.label])
            t_truth = truth["t"].to_numpy()
            duration = float(
                max(t_truth[-1], frames_t["t_end_s"].max() if len(frames_t) else 0)
            )
            if np.isfinite(onset):
                end = contact_end(t_truth, truth[self.area_column].to_numpy(), onset)
                s = bin_scores(
                    frames_t,
                    onset_s=onset,
                    end_s=end,
                    duration_s=duration,
                    bin_s=self.bin_s,
                )
            else:  # no slip in this trial: every detection is a false positive
                s = bin_scores(
                    frames_t,
                    onset_s=np.inf,
                    end_s=np.inf,
                    duration_s=duration,
                    bin_s=self.bin_s,
                )
                end = float("nan")
            rows.append(
                {
                    "trial_id": trial.trial_id,
                    "group": str(trial.meta.get(self.group, "")),
                    "onset_s": onset,
                    "end_s": end,
                    **s,
                    **prf(s["tp"], s["fp"], s["fn"]),
                    "latency_ms": 1e3 * s["latency_s"],
                    "vibration_frames": int((frames_t["incident"] == 1).sum()),
                    "slip_frames": int(frames_t["slip"].sum()),
                }
            )
            frames.append(
                frames_t.assign(trial_id=trial.trial_id).drop(columns="segment")
            )
        table = pd.DataFrame(rows)
        all_frames = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
        return table, all_frames

    @staticmethod
    def summarise(table: pd.DataFrame) -> dict[str, Any]:
        """Mean over trials (the paper's Table 1), pooled counts, latency stats, per group."""

        def block(part: pd.DataFrame) -> dict[str, Any]:
            lat = part["latency_ms"].to_numpy(dtype=np.float64)
            hit = lat[np.isfinite(lat)]
            tp, fp, fn = (int(part[c].sum()) for c in ("tp", "fp", "fn"))
            return {
                "n_trials": len(part),
                "mean": {
                    k: float(np.nanmean(part[k])) if part[k].notna().any() else np.nan
                    for k in ("precision", "sensitivity", "f1")
                },
                "pooled": {"tp": tp, "fp": fp, "fn": fn, **prf(tp, fp, fn)},
                "latency_ms": {
                    "mean": float(hit.mean()) if len(hit) else np.nan,
                    "sd": float(hit.std(ddof=1)) if len(hit) > 1 else np.nan,
                    "median": float(np.median(hit)) if len(hit) else np.nan,
                    "under_10ms": int((hit < 10.0).sum()),
                    "missed": int(len(lat) - len(hit)),
                },
            }

        out = block(table)
        out["by_group"] = {str(g): block(p) for g, p in table.groupby("group")}
        return out

    def _truths_scores(
        self, dataset: Dataset, frames: pd.DataFrame
    ) -> tuple[list[TrialTruth], list[NDArray[np.float64]]]:
        """Each trial's truth and its frames' slip decisions (1: slip) at the frame ends."""
        truths, scores = [], []
        for trial in dataset:
            f = frames[frames["trial_id"] == trial.trial_id] if len(frames) else frames
            t = f["t_end_s"].to_numpy(np.float64) if len(f) else np.empty(0)
            onset = float(trial.labels.get(self.label, np.nan))
            onset = onset if np.isfinite(onset) else np.nan
            truths.append(
                TrialTruth(trial.trial_id, t, slipped_of(trial.labels, onset), onset)
            )
            scores.append(f["slip"].to_numpy(np.float64) if len(f) else np.empty(0))
        return truths, scores

    def trial_events(
        self, dataset: Dataset, frames: pd.DataFrame, debounce_k: int = 1
    ) -> tuple[dict[str, Any], pd.DataFrame]:
        """The trial events of the detector's slip frames (an alarm at the
        ``debounce_k``-th consecutive frame it declares slip;
        :mod:`slipkit.evaluate.events`): the ``operating_point`` summary and the
        per-trial table."""
        truths, scores = self._truths_scores(dataset, frames)
        summary, events = evaluate_point(truths, scores, 0.5, debounce_k, self.cost)
        point = {"threshold": float("nan"), "debounce_k": int(debounce_k), **summary}
        return point, events_table(events, self.cost)

    def choose_debounce(
        self, dataset: Dataset, frames: pd.DataFrame
    ) -> OperatingPoint | None:
        """The debounce of lowest mean cost within the limits on these (training)
        trials' frames (:func:`~slipkit.evaluate.events.choose_operating_point`, the
        threshold fixed at the detector's decision); None without ``operating_point``."""
        if self.operating_point is None:
            return None
        truths, scores = self._truths_scores(dataset, frames)
        return choose_operating_point(
            truths,
            scores,
            thresholds=[0.5],
            debounce_ks=self.operating_point["debounce"],
            cost=self.cost,
            limits=self.limits,
        )

    def _source(self, n_trials: int, learned: bool) -> str:
        c, lim = self.cost, self.limits
        limits = (
            f", early alarms <= {lim.max_early_alarm_rate * 100:g} % of trials"
            if lim.max_early_alarm_rate is not None
            else ""
        )
        if lim.max_alarms_per_disturbance is not None:
            limits += (
                f", alarms on <= {lim.max_alarms_per_disturbance * 100:g} % of "
                "disturbances"
            )
        what = (
            "the trials the classifier was fitted on (in-sample)"
            if learned
            else "trials the rule learns nothing from"
        )
        return (
            f"lowest mean trial cost (miss {c.miss:g}, early alarm {c.early_alarm:g}, "
            f"{c.delay_ms:g} per ms of delay{limits}) over debounce "
            f"{self.operating_point['debounce'] if self.operating_point else [1]} on "
            f"the {n_trials} training trials, {what}"
        )

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        split = split_by_trial(dataset, test_size=self.test_size, seed=seed)
        train, _, test = split.apply(dataset)
        X, seg = self._events_xy(train)
        learned = "onsets" in inspect.signature(model.fit).parameters
        if learned:
            # A learned estimator (slipkit.families.davis.classifier): the scoring truth per recording.
            onsets, ends = self._truth_spans(train)
            model.fit(X, segments=seg, onsets=onsets, ends=ends)
        else:  # the rule: fit checks parameters and events, nothing is learned
            model.fit(X, segments=seg)
        train_table, train_frames = self.trial_table(model, train)
        chosen = self.choose_debounce(train, train_frames)
        k = chosen.debounce_k if chosen is not None else 1
        model.debounce_k_ = k  # the deployed debounce; evaluate scores at it
        record = (
            {**chosen.record(self._source(len(train), learned)), "threshold": None}
            if chosen is not None
            else {
                "threshold": None,
                "debounce_k": 1,
                "from": "fixed: the detector's own rule, debounce 1",
            }
        )
        # the test side, scored once at the chosen debounce
        table, frames = self.trial_table(model, test)
        table.to_csv(out / "davis_trials.csv", index=False)
        frames.to_csv(out / "test_frames.csv", index=False)
        point, events = self.trial_events(test, frames, k)
        events.to_csv(out / "test_events.csv", index=False)
        metrics = {
            "split": {"train": list(split.train), "test": list(split.test)},
            "bin_s": self.bin_s,
            "paper": PAPER,
            "validation": {
                "cv": "none: scored on the training trials it was fitted on "
                "(an optimistic figure)"
                if learned
                else "none: a fixed rule (fit learns nothing), scored on the "
                "training trials",
                **self.summarise(train_table),
            },
            "test": {**self.summarise(table), "operating_point": point},
            "operating_point": record,
        }
        return TaskResult(model, metrics, _summary(metrics))

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        table, frames = self.trial_table(model, dataset)
        table.to_csv(out / "davis_trials.csv", index=False)
        frames.to_csv(out / "frames.csv", index=False)
        k = int(getattr(model, "debounce_k_", 1))  # the run's chosen debounce
        point, events = self.trial_events(dataset, frames, k)
        events.to_csv(out / "events.csv", index=False)
        return {
            "paper": PAPER,
            "test": {**self.summarise(table), "operating_point": point},
        }


def _summary(metrics: Mapping[str, Any]) -> list[str]:
    t = metrics["test"]
    m, lat, op = t["mean"], t["latency_ms"], t["operating_point"]
    return [
        f"DAVIS event-polarity detector, {t['n_trials']} test trials, "
        f"{metrics['bin_s'] * 1e3:.0f} ms bins (mean over trials):",
        f"  {'':<10}{'precision':>10}{'sensitivity':>12}{'F1':>6}{'latency ms (sd)':>18}",
        f"  {'slipkit':<10}{m['precision']:>10.2f}{m['sensitivity']:>12.2f}{m['f1']:>6.2f}"
        f"{lat['mean']:>10.1f} ({lat['sd']:.1f})",
        f"  {'paper':<10}{PAPER['precision']:>10.2f}{PAPER['sensitivity']:>12.2f}"
        f"{PAPER['f1']:>6.2f}{PAPER['latency_ms']:>10.1f} ({PAPER['latency_sd_ms']:.1f})",
        f"  latency under 10 ms: {lat['under_10ms']}/{t['n_trials']} trials "
        f"(paper: 11/37); missed: {lat['missed']}",
        f"  trial events at debounce {op['debounce_k']}: detected "
        f"{op['detected_rate'] * 100:.0f} %, early alarms "
        f"{op['early_alarm_rate'] * 100:.0f} %, cost {op['cost']:.3f} per trial",
    ]


# the polarity rule (and its onset subclass) reads the events inside this task: learned-model
# tasks refuse it
register_analytic_estimator(_DavisPolarity)

__all__: Sequence[str] = ["PAPER", "DavisRelease"]
