"""Slip type (or direction) from windows of electrode frames (Su et al. 2015, Sec. IV-C).

Every trial carries one class label (``slip_class``: linear / rotational on the
simulated BioTac lift; ``slip_class`` = direction or ``slip_type`` on BioTacSP-DoS).
Windows of ``W`` consecutive frames are cut from one stream
(:func:`slipkit.features.windows.sliding_windows`), each labelled with its trial's
class and known by the time of its last frame. Trials (never windows) are split:
stratified by class, or by a group (``object``: the test objects are unseen), once or
in ``folds`` so that every trial is tested once by a model that never saw it.

Reported: per-window accuracy on the test side (the objective, ``accuracy``), balanced
accuracy, per-class recall and confusion, the same per sequence (majority vote over a
trial's windows), three controls - *first frame only* (each window replaced by its
trial's first frame: what the static contact alone predicts), *dynamics only* (each
frame minus the trial's, or the window's, first frame), both fitted as clones of the
model, and the *majority class* of the training side -, accuracy against the time of
the window's last frame (relative to the slip onset when the dataset labels it: the
paper's Fig. 10; else to the trial start), accuracy against the window length (each
length refitted), and optional other models on the same split.

Model selection without leaks: a model that chooses among candidates
(:class:`slipkit.models.selection.CandidateSearch`) is fitted once per outer fold on
that fold's training windows, with ``groups`` = each window's object, so its
leave-one-object-out CV never sees a test object (nested CV). The controls and the
width sweep refit what each fold chose rather than selecting again. The saved model
selects again by leave-one-object-out CV over every object and is refitted on all.
Each finished fold prints a progress line on stderr (step i of n, fold, elapsed, ETA).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import pandas as pd
from sklearn.base import ClassifierMixin as _ClassifierMixin
from sklearn.base import clone
from sklearn.dummy import DummyClassifier
from sklearn.model_selection import GroupKFold, StratifiedGroupKFold

from slipkit.data.dataset import Dataset
from slipkit.data.splits import split_by_group, split_by_trial
from slipkit.errors import SlipkitError
from slipkit.evaluate.metrics import classification_metrics
from slipkit.features.windows import (
    MODES,
    NAN_POLICIES,
    Mode,
    NanPolicy,
    frames_for_ms,
    sliding_windows,
)
from slipkit.models.selection import fit_with_groups
from slipkit.progress import progress_line
from slipkit.train.task import Task, TaskResult, analytic_estimators
from slipkit.train.tasks.slip_type_plots import _pct, _plot_time, _width_outputs

log = logging.getLogger("slipkit.slip_type")

__all__ = ["WindowClassification", "WindowSet", "accuracy_vs_time", "majority_vote"]


@dataclass
class WindowSet:
    """The windows of a set of trials.

    Attributes
    ----------
    X : ndarray of shape (n_windows, width * n_channels)
        Flattened windows.
    y : ndarray of str, shape (n_windows,)
        Class of each window's trial.
    trial : ndarray of str, shape (n_windows,)
        Trial id of each window.
    t_rel : ndarray of float, shape (n_windows,)
        Time of the window's last frame, s, relative to the trial's slip onset (or
        to the trial start when the task has no onset label).
    group : ndarray of str, shape (n_windows,)
        What a model's inner cross-validation and early-stopping split keep whole:
        the window's object (the task's ``group``) under ``split="group"``, else its
        trial.
    """

    X: np.ndarray
    y: np.ndarray
    trial: np.ndarray
    t_rel: np.ndarray
    group: np.ndarray

    def __len__(self) -> int:
        return len(self.y)

    def take(self, mask: np.ndarray) -> WindowSet:
        """The windows where ``mask`` is true."""
        return WindowSet(
            self.X[mask],
            self.y[mask],
            self.trial[mask],
            self.t_rel[mask],
            self.group[mask],
        )


def majority_vote(
    trial: np.ndarray,
    pred: np.ndarray,
    proba: np.ndarray | None,
    classes: Sequence[Any],
) -> pd.DataFrame:
    """One prediction per trial: the class most of its windows get.

    Ties go to the tied class with the highest summed probability (or the first
    in ``classes`` without probabilities). Returns columns ``trial_id``, ``pred``,
    ``n_windows``, ``vote_share`` (share of the trial's windows for ``pred``).
    """
    classes = list(classes)
    rows = []
    for tid in dict.fromkeys(trial):
        sel = trial == tid
        counts = np.array([np.sum(pred[sel] == c) for c in classes], dtype=float)
        best = counts == counts.max()
        if best.sum() > 1 and proba is not None:
            score = np.where(best, proba[sel].sum(axis=0), -np.inf)
            k = int(np.argmax(score))
        else:
            k = int(np.argmax(counts))
        rows.append(
            {
                "trial_id": tid,
                "pred": classes[k],
                "n_windows": int(sel.sum()),
                "vote_share": float(counts[k] / sel.sum()),
            }
        )
    return pd.DataFrame(rows)


def accuracy_vs_time(
    t_rel: np.ndarray, correct: Mapping[str, np.ndarray], bin_s: float
) -> pd.DataFrame:
    """Accuracy of windows grouped by the time of their last frame.

    Parameters
    ----------
    t_rel : ndarray of float
        Time of each window's last frame, s (relative to the slip onset or trial start).
    correct : mapping of str to ndarray of bool
        Per-window correctness of each model (e.g. ``model``, ``first_frame``).
    bin_s : float
        Bin width, s; a window counts in the bin of ``round(t_rel / bin_s) * bin_s``.

    Returns
    -------
    DataFrame
        One row per bin with any window: ``t_rel_s`` (bin centre), ``n_windows`` and
        one ``accuracy_<name>`` column per model.
    """
    if not bin_s > 0:
        raise ValueError(f"bin_s must be > 0 s; got {bin_s}")
    key = np.round(np.asarray(t_rel) / bin_s).astype(np.int64)
    frame = pd.DataFrame(
        {
            "bin": key,
            **{f"accuracy_{k}": np.asarray(v, dtype=float) for k, v in correct.items()},
        }
    )
    grouped = frame.groupby("bin", sort=True)
    table = grouped.mean()
    table.insert(0, "n_windows", grouped.size())
    # round: bin centres as written (0.3, not 0.30000000000000004) in the csv
    table.insert(0, "t_rel_s", np.round(table.index.to_numpy() * bin_s, 9))
    return table.reset_index(drop=True)


def _fit(model: Any, X: np.ndarray, y: np.ndarray, groups: np.ndarray) -> Any:
    """``model.fit``, passing each window's group (object or trial) when it takes ``groups``."""
    return fit_with_groups(model, X, y, groups)


def _cost(model: Any) -> dict[str, Any]:
    return {
        "n_parameters": getattr(model, "n_parameters_", None),
        "flops_per_window": getattr(model, "flops_per_window_", None),
        "n_epochs": getattr(model, "n_epochs_", None),
    }


class WindowClassification(Task):
    """Per-window classification of a trial-level class from windows of one stream.

    Parameters
    ----------
    label : str
        Trial class label (``slip_class``, ``slip_type``).
    stream : str
        Sampled stream the windows are cut from (``electrodes``).
    channels : sequence of str or None
        Channels to use, in order; None: all of the stream's.
    window : float
        Window length W, in ``unit`` (paper: 100 frames at 300 Hz).
    hop : float
        Step between window starts, in ``unit`` (at least one frame).
    unit : {"frames", "ms"}
        Unit of ``window``, ``hop`` and ``sweep`` (ms are rounded to whole frames at
        the stream's rate, at least 1).
    mode : {"raw", "window", "trial", "first_frame"}
        What the main model's windows hold (see :mod:`slipkit.features.windows`).
    dynamics : {"trial", "window"} or None
        Mode of the dynamics-only variant (a clone of the model); None skips it.
    first_frame_control : bool
        Fit a clone on first-frame-only windows (the static-contact control).
    onset_label : str or None
        Trial label giving the slip onset, s; window times are relative to it. None,
        or a dataset whose onsets are all NaN: relative to the trial start.
    reference_label : str or None
        A later onset (``reference_onset_s``: the IMU) drawn on the time plot at its
        median lag.
    window_end_s : [low, high] or None
        Keep, for training and the headline, windows whose last frame lies in
        ``[low, high]`` s relative to the onset (or trial start); None keeps all.
    curve_s : [low, high] or None
        Time range of test windows for ``accuracy_vs_time`` (None: ``window_end_s``
        or all).
    curve_bin_s : float or None
        Bin of the time curve, s (None: the hop).
    split : {"trial", "group"}
        Unit that never crosses sides: trials (stratified by class) or values of
        ``group`` (unseen objects).
    group : str
        Group column for ``split="group"``.
    test_size : float
        Share of trials (or groups) tested, with ``folds`` null or 1.
    folds : int or None
        >= 2: k-fold over trials (stratified) or groups (every object tested once,
        pooled); the saved model is then refitted on every trial.
    sweep : sequence of float
        Window lengths (``unit``) for ``accuracy_vs_width``, each a refitted clone;
        empty skips it.
    compare : mapping of str to estimator, optional
        Other models fitted and scored on the same split (e.g. ``cnn``), with their
        parameter count and FLOPs per window.
    published : mapping, optional
        ``{accuracy: 0.8256, what: "..."}``: a published figure printed beside ours.
    nan_policy : {"raise", "omit", "propagate"}
        Non-finite frames (see :func:`~slipkit.features.windows.sliding_windows`).
    """

    accepts = (_ClassifierMixin,)
    refuses = analytic_estimators()
    feeds = "fits a learned classifier on windows of stream {stream}"

    #: a validation score on the training side only (the saved model's leave-one-object-out
    #: selection score, or a group k-fold of the fixed model): what a sweep may optimise
    objective = "validation.balanced_accuracy"
    direction = "maximize"
    #: (step, steps) of the progress lines on stderr, set at the start of each fit
    _phase_counter: tuple[int, int] = (1, 1)

    def __init__(
        self,
        *,
        label: str = "slip_class",
        stream: str = "electrodes",
        channels: Sequence[str] | None = None,
        window: float = 100,
        hop: float = 3,
        unit: str = "frames",
        mode: str = "raw",
        dynamics: str | None = "trial",
        first_frame_control: bool = True,
        onset_label: str | None = "slip_onset_s",
        reference_label: str | None = None,
        window_end_s: Sequence[float] | None = None,
        curve_s: Sequence[float] | None = None,
        curve_bin_s: float | None = None,
        split: str = "trial",
        group: str = "object",
        test_size: float = 0.2,
        folds: int | None = None,
        sweep: Sequence[float] = (),
        compare: Mapping[str, Any] | None = None,
        published: Mapping[str, Any] | None = None,
        nan_policy: str = "raise",
    ) -> None:
        self.label = label
        self.stream = stream
        self.channels = None if channels is None else list(channels)
        self.window = window
        self.hop = hop
        self.unit = unit
        self.mode = mode
        self.dynamics = dynamics
        self.first_frame_control = first_frame_control
        self.onset_label = onset_label
        self.reference_label = reference_label
        self.window_end_s = None if window_end_s is None else list(window_end_s)
        self.curve_s = None if curve_s is None else list(curve_s)
        self.curve_bin_s = curve_bin_s
        self.split = split
        self.group = group
        self.test_size = test_size
        self.folds = folds
        self.sweep = list(sweep)
        self.compare = dict(compare or {})
        self.published = dict(published or {})
        self.nan_policy = nan_policy
        if unit not in ("frames", "ms"):
            raise SlipkitError(f"task.unit must be 'frames' or 'ms'; got {unit!r}")
        if mode not in MODES or (
            dynamics is not None and dynamics not in ("trial", "window")
        ):
            raise SlipkitError(
                f"task.mode must be one of {MODES} and task.dynamics 'trial', 'window' "
                f"or null; got mode={mode!r}, dynamics={dynamics!r}"
            )
        if split not in ("trial", "group"):
            raise SlipkitError(f"task.split must be 'trial' or 'group'; got {split!r}")
        if nan_policy not in NAN_POLICIES:
            raise SlipkitError(
                f"task.nan_policy must be one of {NAN_POLICIES}; got {nan_policy!r}"
            )

    # -- windows ----------------------------------------------------------------
    def rate_hz(self, dataset: Dataset) -> float:
        """Frame rate of the task's stream, Hz."""
        if self.stream not in dataset.streams:
            raise SlipkitError(
                f"dataset {dataset.name!r} has no stream {self.stream!r}; streams: {sorted(dataset.streams)}"
            )
        rate = dataset.streams[self.stream].rate_hz
        if rate is None:
            raise SlipkitError(
                f"stream {self.stream!r} is not sampled (no frame rate); window tasks need frames"
            )
        return float(rate)

    def frames(self, value: float, dataset: Dataset) -> int:
        """``value`` (in ``unit``) as whole frames of the stream."""
        if self.unit == "frames":
            if int(value) != value or value < 1:
                raise SlipkitError(
                    f"window lengths in frames must be whole numbers >= 1; got {value}"
                )
            return int(value)
        return frames_for_ms(float(value), self.rate_hz(dataset))

    def classes(self, dataset: Dataset) -> list[str]:
        """The label's declared classes (or the sorted values present)."""
        if self.label not in dataset.trials.columns:
            raise SlipkitError(
                f"dataset {dataset.name!r} has no label {self.label!r}; trial columns: {list(dataset.trials.columns)}"
            )
        try:
            return list(dataset.class_names(self.label))
        except KeyError:
            return sorted(map(str, dataset.trials[self.label].dropna().unique()))

    def _origin_is_onset(self, dataset: Dataset) -> bool:
        if self.onset_label is None or self.onset_label not in dataset.trials.columns:
            return False
        return bool(
            np.isfinite(dataset.trials[self.onset_label].to_numpy(dtype=float)).any()
        )

    def windows(
        self, dataset: Dataset, width: int, mode: str, *, span: Sequence[float] | None
    ) -> WindowSet:
        """Windows of every trial whose last frame lies in ``span`` (s, relative)."""
        rate = self.rate_hz(dataset)
        hop = self.frames(self.hop, dataset)
        spec = dataset.streams[self.stream]
        channels = list(spec.channels) if self.channels is None else self.channels
        missing = [c for c in channels if c not in spec.channels]
        if missing:
            raise SlipkitError(
                f"stream {self.stream!r} has no channels {missing}; channels: {list(spec.channels)}"
            )
        by_onset = self._origin_is_onset(dataset)
        by_group = self.split == "group" and self.group in dataset.trials.columns
        table = dataset.stream(self.stream)
        rows = table.groupby("trial_id", sort=False).indices  # trial -> row positions
        values = table[channels].to_numpy(dtype=np.float64)
        times = table["t"].to_numpy(dtype=np.float64)
        parts: list[WindowSet] = []
        for rec in dataset.trials.itertuples(index=False):
            tid = str(rec.trial_id)
            cls = getattr(rec, self.label)
            idx = rows.get(tid)
            if idx is None or pd.isna(cls):
                continue
            t = times[idx]
            try:
                win = sliding_windows(
                    values[idx],
                    width,
                    hop=hop,
                    mode=cast(Mode, mode),  # checked against MODES in __init__
                    nan_policy=cast(NanPolicy, self.nan_policy),
                )
            except ValueError as exc:
                raise SlipkitError(
                    f"trial {tid!r}, stream {self.stream!r}: {exc}"
                ) from None
            origin = (
                float(getattr(rec, str(self.onset_label))) if by_onset else float(t[0])
            )
            rel = t[win.end] - origin
            keep = np.isfinite(rel)
            if span is not None:
                keep &= (rel >= span[0] - 1e-9) & (rel <= span[1] + 1e-9)
            n = int(keep.sum())
            unit = str(getattr(rec, self.group)) if by_group else tid
            parts.append(
                WindowSet(
                    win.X[keep],
                    np.full(n, str(cls), dtype=object),
                    np.full(n, tid, dtype=object),
                    rel[keep],
                    np.full(n, unit, dtype=object),
                )
            )
        if not parts or sum(len(p) for p in parts) == 0:
            raise SlipkitError(
                f"no windows of {width} frames ({width / rate * 1000:.0f} ms) in dataset "
                f"{dataset.name!r} (stream {self.stream!r}, window_end_s={span}); trials "
                "may be shorter than a window or end outside the range"
            )
        return WindowSet(
            np.concatenate([p.X for p in parts]),
            np.concatenate([p.y for p in parts]),
            np.concatenate([p.trial for p in parts]),
            np.concatenate([p.t_rel for p in parts]),
            np.concatenate([p.group for p in parts]),
        )

    def _curve_span(self) -> list[float] | None:
        if self.curve_s is not None:
            return self.curve_s
        return self.window_end_s

    def _span_union(self) -> list[float] | None:
        a, b = self.window_end_s, self._curve_span()
        if a is None or b is None:
            return None
        return [min(a[0], b[0]), max(a[1], b[1])]

    def _in_span(self, t_rel: np.ndarray) -> np.ndarray:
        if self.window_end_s is None:
            return np.ones(len(t_rel), dtype=bool)
        lo, hi = self.window_end_s
        return (t_rel >= lo - 1e-9) & (t_rel <= hi + 1e-9)

    # -- splits -----------------------------------------------------------------
    def splits(
        self, dataset: Dataset, seed: int
    ) -> list[tuple[tuple[str, ...], tuple[str, ...]]]:
        """(train ids, test ids) of each fold (one pair without ``folds``)."""
        ids = np.asarray(dataset.trial_ids, dtype=object)
        y = dataset.trials[self.label].astype(str).to_numpy()
        k = int(self.folds or 1)
        if self.split == "group" and self.group not in dataset.trials.columns:
            raise SlipkitError(
                f"task.group {self.group!r} is not a column of the trials table; columns: {list(dataset.trials.columns)}"
            )
        if k < 2:
            if self.split == "group":
                s = split_by_group(
                    dataset, self.group, test_size=self.test_size, seed=seed
                )
            else:
                s = split_by_trial(
                    dataset, test_size=self.test_size, seed=seed, stratify=self.label
                )
            return [(s.train, s.test)]
        if self.split == "group":
            groups = dataset.trials[self.group].astype(str).to_numpy()
            if len(set(groups)) < k:
                raise SlipkitError(
                    f"task.folds={k} needs >= {k} values of {self.group!r}; got {len(set(groups))}"
                )
            gen = GroupKFold(n_splits=k, shuffle=True, random_state=seed).split(
                ids, y, groups
            )
        else:
            # One trial per group: a stratified k-fold over trials.
            gen = StratifiedGroupKFold(
                n_splits=k, shuffle=True, random_state=seed
            ).split(ids, y, ids)
        return [(tuple(map(str, ids[tr])), tuple(map(str, ids[te]))) for tr, te in gen]

    # -- fit / score ---------------------------------------------------------------
    def _fit_score(
        self,
        model: Any,
        dataset: Dataset,
        folds: list[tuple[tuple[str, ...], tuple[str, ...]]],
        width: int,
        mode: str,
        *,
        curve: bool,
        phase: str = "model",
        chosen: bool = False,
    ) -> tuple[Any, pd.DataFrame]:
        """Fit a clone per fold; every test window's prediction (pooled over folds).

        A model that selects among candidates (``selection_``) does so inside each
        fold's training objects only; the fold's record is kept in
        ``self.fold_selections_[phase]``. With ``chosen``, fold ``k`` fits what the
        main model's fold ``k`` chose (its ``best_estimator_``, unfitted) instead of
        selecting again: the controls and the width sweep then measure the chosen
        pipeline on other inputs, at the cost of one fit per fold.
        """
        span = self._span_union() if curve else self.window_end_s
        tables = []
        fitted = model
        selections = self.fold_selections_.setdefault(phase, [])
        t0 = time.perf_counter()
        for k, (train_ids, test_ids) in enumerate(folds):
            train = self.windows(
                dataset.subset(train_ids), width, mode, span=self.window_end_s
            )
            test = self.windows(dataset.subset(test_ids), width, mode, span=span)
            base = model
            if chosen and k < len(self.fold_models_.get("model", [])):
                base = getattr(self.fold_models_["model"][k], "best_estimator_", model)
            fitted = clone(base)
            _fit(fitted, train.X, train.y, train.group)
            if phase == "model":
                self.fold_models_.setdefault(phase, []).append(fitted)
            if hasattr(fitted, "selection_"):
                sel = fitted.selection_
                selections.append(
                    {"fold": k, "best": sel["best"], "best_score": sel["best_score"]}
                )
            self._progress(phase, k + 1, len(folds), t0)
            proba = (
                fitted.predict_proba(test.X)
                if hasattr(fitted, "predict_proba")
                else None
            )
            pred = (
                np.asarray(fitted.classes_)[np.argmax(proba, axis=1)]
                if proba is not None
                else np.asarray(fitted.predict(test.X))
            )
            table = pd.DataFrame(
                {
                    "fold": k,
                    "trial_id": test.trial,
                    "t_rel_s": test.t_rel,
                    "label": test.y,
                    "pred": pred.astype(str),
                }
            )
            table["in_span"] = self._in_span(test.t_rel)
            if proba is not None:
                for j, c in enumerate(fitted.classes_):
                    table[f"p_{c}"] = proba[:, j]
            tables.append(table)
            log.info(
                "fold %d, W=%d frames, mode %s: %d train windows (%d trials), %d test windows (%d trials)",
                k,
                width,
                mode,
                len(train),
                len(train_ids),
                len(test),
                len(test_ids),
            )
        return fitted, pd.concat(tables, ignore_index=True)

    def _progress(self, phase: str, done: int, total: int, t0: float) -> None:
        """One stderr line per finished fold: phase i of n, fold, elapsed, ETA."""
        elapsed = time.perf_counter() - t0
        eta = elapsed / done * (total - done)
        step, steps = self._phase_counter
        progress_line(
            f"slipkit train: [{step}/{steps}] {phase}: fold {done}/{total} done, "
            f"{elapsed:.0f} s elapsed, ETA {eta:.0f} s for this step"
        )
        if done == total:
            self._phase_counter = (step + 1, steps)

    def _score(self, table: pd.DataFrame, classes: list[str]) -> dict[str, Any]:
        """Window and sequence metrics of the in-span rows of a predictions table."""
        rows = table[table["in_span"]]
        window = classification_metrics(rows["label"], rows["pred"], classes)
        pcols = [f"p_{c}" for c in classes]
        proba = rows[pcols].to_numpy() if all(c in rows for c in pcols) else None
        votes = majority_vote(
            rows["trial_id"].to_numpy(), rows["pred"].to_numpy(), proba, classes
        )
        truth = rows.groupby("trial_id", sort=False)["label"].first()
        sequence = classification_metrics(
            truth.loc[votes["trial_id"]].to_numpy(), votes["pred"].to_numpy(), classes
        )
        return {"window": window, "sequence": sequence}

    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        classes = self.classes(dataset)
        rate = self.rate_hz(dataset)
        width = self.frames(self.window, dataset)
        folds = self.splits(dataset, seed)
        variants = []
        if self.first_frame_control:
            variants.append(("first_frame", "first_frame"))
        if self.dynamics is not None:
            variants.append(("dynamics", self.dynamics))
        self.fold_selections_: dict[str, list[dict[str, Any]]] = {}
        self.fold_models_: dict[str, list[Any]] = {}
        self._phase_counter = (
            1,
            3
            + len(variants)
            + len(self.compare)
            + len(self.sweep)
            + int(len(folds) > 1),
        )
        fitted, table = self._fit_score(
            model, dataset, folds, width, self.mode, curve=True
        )
        main = self._score(table, classes)
        curves: dict[str, pd.DataFrame] = {"model": table}
        controls: dict[str, Any] = {}
        # Majority class of each fold's training side: what predicting without data scores.
        _, t_maj = self._fit_score(
            DummyClassifier(strategy="most_frequent"),
            dataset,
            folds,
            width,
            self.mode,
            curve=False,
            phase="majority",
        )
        for name, mode in variants:
            _, t_ctl = self._fit_score(
                model, dataset, folds, width, mode, curve=True, phase=name, chosen=True
            )
            controls[name] = {"mode": mode, **self._score(t_ctl, classes)}
            curves[name] = t_ctl
        controls["majority"] = {"mode": "most_frequent", **self._score(t_maj, classes)}
        others: dict[str, Any] = {}
        for name, other in self.compare.items():
            fitted_o, t_o = self._fit_score(
                other, dataset, folds, width, self.mode, curve=False, phase=name
            )
            others[name] = {
                "estimator": type(other).__name__,
                **self._score(t_o, classes),
                **_cost(fitted_o),
            }
        by_width = []
        for w in self.sweep:
            frames = self.frames(w, dataset)
            _, t_w = self._fit_score(
                model,
                dataset,
                folds,
                frames,
                self.mode,
                curve=False,
                phase=f"window {w:g} {self.unit}",
                chosen=True,
            )
            s = self._score(t_w, classes)
            by_width.append(
                {
                    "window": float(w),
                    "unit": self.unit,
                    "frames": frames,
                    "ms": frames / rate * 1000.0,
                    "accuracy": s["window"]["accuracy"],
                    "sequence_accuracy": s["sequence"]["accuracy"],
                    "n_windows": s["window"]["n"],
                }
            )
        if len(folds) > 1:
            # Every trial was tested once; the model to save is fitted on all of them.
            every = self.windows(dataset, width, self.mode, span=self.window_end_s)
            t0 = time.perf_counter()
            fitted = _fit(clone(model), every.X, every.y, every.group)
            self._progress("refit on every trial", 1, 1, t0)
        else:
            every = self.windows(
                dataset.subset(folds[0][0]), width, self.mode, span=self.window_end_s
            )
        validation = self._validation(fitted, model, every)
        table.to_csv(out / "test_predictions.csv", index=False)
        vs_time = self._time_outputs(curves, dataset, out)
        if by_width:
            _width_outputs(pd.DataFrame(by_width), out, self.unit)
        test_trials = dataset.trials.set_index("trial_id").loc[
            sorted(set(table["trial_id"]))
        ]
        majority = float(
            test_trials[self.label].astype(str).value_counts(normalize=True).max()
        )
        metrics: dict[str, Any] = {
            "accuracy": main["window"]["accuracy"],
            "balanced_accuracy": main["window"]["balanced_accuracy"],
            "sequence_accuracy": main["sequence"]["accuracy"],
            "selection": self._selection(fitted),
            "validation": validation,
            "first_frame_accuracy": controls.get("first_frame", {})
            .get("window", {})
            .get("accuracy"),
            "dynamics_accuracy": controls.get("dynamics", {})
            .get("window", {})
            .get("accuracy"),
            "majority_accuracy": controls["majority"]["window"]["accuracy"],
            "label": self.label,
            "classes": classes,
            "chance": 1.0 / len(classes),
            "majority_baseline_test": majority,
            "window": {
                "frames": width,
                "ms": width / rate * 1000.0,
                "hop_frames": self.frames(self.hop, dataset),
                "mode": self.mode,
                "rate_hz": rate,
            },
            "window_end_s": self.window_end_s,
            "time_origin": self.onset_label
            if self._origin_is_onset(dataset)
            else "trial_start",
            "split": {
                "by": self.split if self.split == "trial" else self.group,
                "folds": len(folds),
                "test": [list(te) for _, te in folds],
                **(
                    {
                        "test_groups": [
                            sorted(
                                set(
                                    dataset.trials.set_index("trial_id")
                                    .loc[list(te), self.group]
                                    .astype(str)
                                )
                            )
                            for _, te in folds
                        ]
                    }
                    if self.split == "group"
                    else {}
                ),
            },
            "test": main["window"],
            "sequence": main["sequence"],
            "controls": controls,
            "model": {"estimator": type(model).__name__, **_cost(fitted)},
            "compare": others,
            "accuracy_vs_width": by_width,
            "accuracy_vs_time": vs_time,
            "published": self.published or None,
        }
        return TaskResult(fitted, metrics, self._summary(metrics))

    def _validation(self, fitted: Any, model: Any, train: WindowSet) -> dict[str, Any]:
        """The saved model's validation score, from its training windows only.

        A search already has it (its chosen candidate's leave-one-object-out mean);
        a fixed model is scored by a group k-fold (k <= 3) over the same groups.
        """
        t0 = time.perf_counter()
        sel = getattr(fitted, "selection_", None)
        if sel is not None:
            best = next(
                c
                for c in sel["candidates"]
                if {"name": c["name"], **c["params"]} == sel["best"]
            )
            self._progress("validation (the selection's)", 1, 1, t0)
            return {
                "cv": sel["cv"],
                "scoring": sel["scoring"],
                sel["scoring"]: sel["best_score"],
                "std": best["std"],
                "from": "selection",
            }
        from slipkit.train.search import group_cv

        k = min(3, len(np.unique(train.group)))
        if k < 2:
            raise SlipkitError(
                f"the validation CV needs >= 2 values of {self.group!r} (or trials) on "
                f"the training side; got {k}"
            )
        record = group_cv(
            model,
            train.X,
            train.y,
            train.group,
            cv=k,
            unit=self.group if self.split == "group" else "trial",
        )
        self._progress("validation", 1, 1, t0)
        return record

    def _selection(self, fitted: Any) -> dict[str, Any] | None:
        """The saved model's selection record, with the per-fold choices beside it.

        ``best`` / ``best_score`` / ``candidates`` are the saved model's (chosen by
        leave-one-object-out CV on every trial it was fitted on); ``per_fold`` holds
        what each outer fold chose on its training objects only, which is what the
        reported test scores come from.
        """
        record = getattr(fitted, "selection_", None)
        if record is None:
            return None
        return {**record, "per_fold": self.fold_selections_.get("model", [])}

    def _time_outputs(
        self,
        tables: Mapping[str, pd.DataFrame],
        dataset: Dataset,
        out: Path,
    ) -> dict[str, Any]:
        """``accuracy_vs_time.csv`` and ``.png``; a short summary for metrics.json.

        ``tables`` maps a model name (``model`` first) to its predictions table; each
        is binned on its own window times (a control may hold other windows, e.g.
        under ``nan_policy="omit"``) and the curves are joined on the bin.
        """
        span = self._curve_span()
        bin_s = self.curve_bin_s or self.frames(self.hop, dataset) / self.rate_hz(
            dataset
        )
        curve: pd.DataFrame | None = None
        for name, tab in tables.items():
            t = tab["t_rel_s"].to_numpy()
            keep = (
                np.ones(len(t), dtype=bool)
                if span is None
                else (t >= span[0] - 1e-9) & (t <= span[1] + 1e-9)
            )
            correct = (tab["label"] == tab["pred"]).to_numpy()[keep]
            part = accuracy_vs_time(t[keep], {name: correct}, bin_s)
            curve = (
                part
                if curve is None
                else curve.merge(
                    part.drop(columns="n_windows"), on="t_rel_s", how="outer"
                )
            )
        assert curve is not None  # tables always holds the model's
        curve.to_csv(out / "accuracy_vs_time.csv", index=False)
        lag = None
        if (
            self.reference_label
            and self.reference_label in dataset.trials.columns
            and self._origin_is_onset(dataset)
        ):
            trials = dataset.trials
            diff = trials[self.reference_label].to_numpy(float) - trials[
                str(self.onset_label)
            ].to_numpy(float)
            lag = float(np.nanmedian(diff)) if np.isfinite(diff).any() else None
        origin = self.onset_label if self._origin_is_onset(dataset) else "trial start"
        _plot_time(
            curve,
            out / "accuracy_vs_time.png",
            origin=str(origin),
            reference=(self.reference_label, lag),
            published=self.published,
        )
        at_ref = None
        if lag is not None:
            before = curve[curve["t_rel_s"] <= lag + 1e-9]
            at_ref = float(before["accuracy_model"].iloc[-1]) if len(before) else None
        return {
            "file": "accuracy_vs_time.csv",
            "bin_s": bin_s,
            "origin": origin,
            "reference_lag_s": lag,
            "accuracy_at_reference": at_ref,
            "n_bins": len(curve),
        }

    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        classes = self.classes(dataset)
        width = self.frames(self.window, dataset)
        ws = self.windows(dataset, width, self.mode, span=self._span_union())
        pred = np.asarray(model.predict(ws.X)).astype(str)
        table = pd.DataFrame(
            {
                "trial_id": ws.trial,
                "t_rel_s": ws.t_rel,
                "label": ws.y,
                "pred": pred,
                "in_span": self._in_span(ws.t_rel),
            }
        )
        table.to_csv(out / "predictions.csv", index=False)
        scores = self._score(table, classes)
        vs_time = self._time_outputs({"model": table}, dataset, out)
        return {
            "accuracy": scores["window"]["accuracy"],
            "sequence_accuracy": scores["sequence"]["accuracy"],
            "window": {"frames": width, "mode": self.mode},
            "accuracy_vs_time": vs_time,
            "test": scores["window"],
            "sequence": scores["sequence"],
        }

    def _summary(self, m: Mapping[str, Any]) -> list[str]:
        w = m["window"]
        pct = _pct
        lines = [
            f"{m['model']['estimator']} on {w['frames']}-frame windows ({w['ms']:.0f} ms at {w['rate_hz']:g} Hz, {w['mode']}), "
            f"label {m['label']} ({len(m['classes'])} classes), split by {m['split']['by']} "
            f"({m['split']['folds']} fold{'s' if m['split']['folds'] > 1 else ''})",
            f"  per window  {pct(m['accuracy'])}  (balanced {pct(m['balanced_accuracy'])}; chance {pct(m['chance'])}, majority {pct(m['majority_baseline_test'])})",
            f"  per trial   {pct(m['sequence_accuracy'])}  (balanced {pct(m['sequence']['balanced_accuracy'])}; majority vote of its windows)",
            "  recall      "
            + ", ".join(f"{c} {pct(r).strip()}" for c, r in m["test"]["recall"].items())
            + " (per window)",
        ]
        val = m.get("validation") or {}
        if val.get("balanced_accuracy") is not None:
            lines.append(
                f"  validation  {pct(val['balanced_accuracy'])}  (balanced, {val['cv']} on the "
                "training side only: the run's objective)"
            )
        sel = m.get("selection")
        if sel:
            best = dict(sel["best"])
            name = best.pop("name", "?")
            params = ", ".join(f"{k}={v}" for k, v in best.items())
            lines.append(
                f"  selected    {name}{f' ({params})' if params else ''}: {sel['scoring']} "
                f"{sel['best_score']:.3f} by {sel['cv']} CV on the training objects "
                f"({len(sel['candidates'])} candidates)"
            )
            if sel.get("per_fold"):
                lines.append(
                    "  per fold    "
                    + "; ".join(
                        f"{f['best'].get('name', '?')} {f['best_score']:.3f}"
                        for f in sel["per_fold"]
                    )
                    + " (each chosen on its own training objects)"
                )
        for name, c in m["controls"].items():
            what = {
                "first_frame": "first frame only",
                "majority": "majority class",
            }.get(name, f"dynamics only ({c['mode']})")
            lines.append(
                f"  {what:<24} window {pct(c['window']['accuracy'])} (balanced "
                f"{pct(c['window']['balanced_accuracy'])}), trial {pct(c['sequence']['accuracy'])}"
            )
        if m["published"]:
            lines.append(
                f"  published   {float(m['published'].get('accuracy', float('nan'))) * 100:.2f} %  {m['published'].get('what', '')}"
            )
        cost = m["model"]
        if cost["n_parameters"] is not None:
            lines.append(
                f"  cost        {cost['n_parameters']} parameters, {cost['flops_per_window']} FLOPs per window"
            )
        for name, o in m["compare"].items():
            lines.append(
                f"  {name:<11} window {pct(o['window']['accuracy'])}, trial {pct(o['sequence']['accuracy'])}; "
                f"{o['n_parameters']} parameters, {o['flops_per_window']} FLOPs per window"
            )
        if m["accuracy_vs_width"]:
            lines.append(
                "  vs window   "
                + ", ".join(
                    f"{r['ms']:.0f} ms {pct(r['accuracy'])}"
                    for r in m["accuracy_vs_width"]
                )
            )
        vt = m["accuracy_vs_time"]
        if vt["accuracy_at_reference"] is not None:
            lines.append(
                f"  at the reference onset (+{vt['reference_lag_s'] * 1000:.0f} ms): {pct(vt['accuracy_at_reference'])} of windows"
            )
        return lines
