"""Recordings of a stream-detection task: trials concatenated with their bounds and truths,
and the per-sample ROC helpers the task uses."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sklearn.metrics import roc_auc_score, roc_curve

from slipkit.baselines.base import segment_bounds
from slipkit.evaluate.events import TrialTruth

FloatArray = NDArray[np.float64]


@dataclass
class Recordings:
    """One stream of a set of trials, concatenated for a detector.

    Attributes
    ----------
    X : ndarray (n_samples, n_channels)
        The stream's channels, trial after trial.
    y : ndarray of int (n_samples,)
        1 = slip sample.
    t : ndarray (n_samples,)
        Sample times (s), restarting in every trial.
    segments : ndarray of int (n_samples,)
        Trial index of every sample.
    trial_ids, groups : list of str
        Per trial.
    onset_s, reference_s : ndarray (n_trials,)
        Slip onset and reference onset per trial (s; NaN = none).
    disturbance : ndarray of bool (n_samples,) or None
        Disturbance samples (a truth column), if asked for.
    rate_hz : float
        The stream's sample rate (Hz).
    slipped : list of bool or None, optional
        Per trial: did it slip (None: unknown; :func:`slipkit.evaluate.events.slipped_of`).
        Not given: a trial slipped when its onset is known.
    """

    X: FloatArray
    y: NDArray[np.int_]
    t: FloatArray
    segments: NDArray[np.int_]
    trial_ids: list[str]
    groups: list[str]
    onset_s: FloatArray
    reference_s: FloatArray
    disturbance: NDArray[np.bool_] | None
    rate_hz: float
    slipped: list[bool | None] | None = None

    def bounds(self) -> list[tuple[int, int]]:
        """(start, stop) of every trial's samples."""
        return segment_bounds(len(self.X), self.segments)

    def truths(self) -> list[TrialTruth]:
        """Each trial's truth for :mod:`slipkit.evaluate.events` (slip samples from ``y``,
        disturbances as intervals of the disturbance samples)."""
        out = []
        for k, (a, b) in enumerate(self.bounds()):
            t = self.t[a:b]
            onset = float(self.onset_s[k])
            slipped = (
                self.slipped[k] if self.slipped is not None else math.isfinite(onset)
            )
            dist: tuple[tuple[float, float], ...] = ()
            if self.disturbance is not None:
                dist = tuple(
                    (float(t[r0]), float(t[r1 - 1]))
                    for r0, r1 in _runs(self.disturbance[a:b])
                )
            out.append(
                TrialTruth(
                    self.trial_ids[k],
                    t,
                    slipped,
                    onset,
                    # unknown onset of a slip: no slip samples to tell time apart
                    slip=self.y[a:b] > 0
                    if slipped is False or math.isfinite(onset)
                    else None,
                    disturbances=dist,
                )
            )
        return out

    def per_trial(self, scores: FloatArray) -> list[FloatArray]:
        """``scores`` cut into one array per trial."""
        return [scores[a:b] for a, b in self.bounds()]


def _runs(flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """(start, stop) of every run of True."""
    f = np.concatenate([[False], flags, [False]]).astype(np.int8)
    d = np.diff(f)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def _roc_choice(y: NDArray[np.int_], s: FloatArray, point: str) -> float:
    """The threshold at the Youden (or closest-to-corner) point of the ROC of (y, s)."""
    low = np.finfo(np.float64).min
    fpr, tpr, thr = roc_curve(y, np.where(np.isfinite(s), s, low))
    ok = np.isfinite(thr) & (thr > low)
    fpr, tpr, thr = fpr[ok], tpr[ok], thr[ok]
    k = (
        int(np.argmax(tpr - fpr))
        if point == "youden"
        else int(np.argmin(np.hypot(fpr, 1.0 - tpr)))
    )
    return float(thr[k])


def _auc(y: NDArray[np.int_], s: FloatArray) -> float:
    if len(np.unique(y)) < 2:
        return float("nan")
    low = np.finfo(np.float64).min
    return float(roc_auc_score(y, np.where(np.isfinite(s), s, low)))


def _rates(y: NDArray[np.int_], pred: NDArray[np.bool_]) -> dict[str, Any]:
    pos, neg = y == 1, y == 0
    tp, fn = int(pred[pos].sum()), int((~pred[pos]).sum())
    fp, tn = int(pred[neg].sum()), int((~pred[neg]).sum())

    def ratio(a: int, b: int) -> float:
        return a / (a + b) if a + b else float("nan")

    return {
        "tp": tp,
        "fn": fn,
        "fp": fp,
        "tn": tn,
        "tpr": ratio(tp, fn),
        "tnr": ratio(tn, fp),
        "fpr": ratio(fp, tn),
        "fnr": ratio(fn, tp),
    }


def _mean_sd(values: Sequence[float]) -> dict[str, Any]:
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)])
    return {
        "n": len(v),
        "mean": float(v.mean()) if len(v) else float("nan"),
        "sd": float(v.std(ddof=1)) if len(v) > 1 else float("nan"),
        "median": float(np.median(v)) if len(v) else float("nan"),
    }
