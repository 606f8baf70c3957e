"""Streaming slip detectors on GelSight pin positions, and the controls they are read beside.

A trial is a mapping ``fingertip -> (n_frames, 2K)`` pin positions (px, the importer's
streams). Every detector gives a score per frame from the frames up to it (a window of
at most ``window`` frames, armed ``arm`` frames after the recording starts), the largest
over the fingertips; it *fires* at the first frame whose score reaches ``threshold_``
and a trial counts as slip when it ever fires. ``horizon`` (frames after arming; None:
the whole recording) limits what a detector watches to the contact phase: it knows the
time since the recording started, never the clip's length. ``fingers="min"`` asks every
fingertip to agree (an object sliding out moves both gels; a wiggle can twist one);
``fingers="first"`` reads the first fingertip alone (``camera_0``).
``threshold_`` is chosen by
:func:`choose_threshold` on out-of-fold trial scores of the training side
(:mod:`slipkit.families.gelsight.report`), never on the trials scored.

* :class:`PinMotionDetector` -- analytic: one pin-field quantity over the window
  (``divergence``: |divergence|; ``contraction``: minus the divergence, the field
  drawing together; ``steady``: translation x straightness, the net drift
  of the field; ``residual``: the non-affine part; ``divergence_per_path``: |divergence|
  over the field's path length in the window, floored at :data:`MIN_PATH` pitches: the
  gel spreading or contracting for its motion, which a shake that moves the field far
  and returns does little of).
* :class:`WindowModelDetector` -- logistic regression (or an RBF SVM) on the window's
  deformation features (:mod:`slipkit.families.gelsight.features`); training frames
  carry their trial's label, weighted so each trial and class counts once. Armed at
  contact with a ``horizon``, it is the learned form of the contact-phase detector.
* :class:`TacTipVelocityDetector` -- the TacTip paper's Gaussian SVM on pin-velocity
  features (:class:`slipkit.models.svm.TacTipSVM`, pooled statistics so any pin count
  works), its decision averaged over the last ``smooth`` frames.

Controls (not streaming; they read what a streaming detector must not):
:class:`ClipLengthControl` (short clip = slip), :class:`FirstFramesControl` (logistic
regression on the first ``arm`` frames, where slip clips open with a marker jump) and
:class:`MajorityControl`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from slipkit.errors import SlipkitError
from slipkit.families.gelsight.features import (
    FEATURES,
    pitch_of,
    to_points,
    trial_features,
)
from slipkit.features.pins import velocity_features
from slipkit.models.svm import TacTipSVM

FloatArray = NDArray[np.float64]
Trial = Mapping[str, FloatArray]

#: the features a learned window model reads, and the transform before scaling
_SIGNED = {"divergence", "curl"}

#: path floor (marker pitches) of ``divergence_per_path``: a field that barely moves
#: (tracking jitter is ~0.01 pitch) must not reach a large ratio
MIN_PATH = 0.02


def choose_threshold(scores: Sequence[float], y: Sequence[int]) -> float:
    """Threshold on trial scores with the best balanced accuracy (slip: score >= it).

    Candidates are the midpoints between consecutive distinct scores (and one below
    and above all); of equally good ones the middle of the widest best run is kept.
    """
    s = np.asarray(scores, dtype=np.float64)
    yy = np.asarray(y, dtype=int)
    s = np.where(np.isfinite(s), s, -1e300)
    u = np.unique(s)
    cand = np.concatenate([[u[0] - 1.0], (u[:-1] + u[1:]) / 2, [u[-1] + 1.0]])
    pos, neg = yy == 1, yy == 0
    fire = s[None, :] >= cand[:, None]
    tpr = fire[:, pos].mean(axis=1) if pos.any() else np.zeros(len(cand))
    tnr = (~fire[:, neg]).mean(axis=1) if neg.any() else np.zeros(len(cand))
    ba = (tpr + tnr) / 2
    best = np.flatnonzero(ba >= ba.max() - 1e-12)
    return float(cand[best[len(best) // 2]])


def first_alarm(frame_scores: FloatArray, threshold: float) -> int | None:
    """First frame whose score reaches ``threshold`` (None: never fires)."""
    hit = np.flatnonzero(np.nan_to_num(frame_scores, nan=-np.inf) >= threshold)
    return int(hit[0]) if len(hit) else None


class _Detector:
    """Shared parts: per-fingertip feature cache, trial scores, alarms."""

    streaming = True

    def __init__(
        self,
        *,
        window: int = 50,
        arm: int = 12,
        horizon: int | None = None,
        fingers: str = "max",
    ) -> None:
        if not 2 <= int(window) <= 50:
            raise SlipkitError(
                f"window={window}: at most 50 frames (2 s at 25 fps), at least 2"
            )
        if horizon is not None and int(horizon) < 1:
            raise SlipkitError(f"horizon={horizon}: at least 1 frame, or None")
        if fingers not in ("max", "min", "first"):
            raise SlipkitError(f"fingers={fingers!r}: expected 'max', 'min' or 'first'")
        self.window, self.arm = int(window), int(arm)
        self.horizon = None if horizon is None else int(horizon)
        self.fingers = fingers
        self.threshold_ = float("nan")

    #: window features by (array id, window, arm), holding the array so the id stays
    #: its own: cross-validation scores the same recordings many times
    _cache: ClassVar[dict[tuple[int, int, int], tuple[FloatArray, FloatArray]]] = {}

    def _features(self, frames: FloatArray) -> FloatArray:
        key = (id(frames), self.window, self.arm)
        hit = self._cache.get(key)
        if hit is not None and hit[0] is frames:
            return hit[1]
        f = trial_features(frames, window=self.window, arm=self.arm)
        if len(self._cache) > 20000:
            self._cache.clear()
        self._cache[key] = (frames, f)
        return f

    def fit(self, trials: Sequence[Trial], y: Sequence[int]) -> _Detector:
        return self

    def finger_scores(self, frames: FloatArray) -> FloatArray:
        """The per-frame score of one fingertip's pin frames. Each streaming detector
        defines its own; a control scores whole trials and has none."""
        raise TypeError(f"{type(self).__name__} scores whole trials, not frames")

    def frame_scores(self, trial: Trial) -> FloatArray:
        """Score per frame over the fingertips (NaN while warming up and after the
        horizon): the largest (``fingers="max"``), the smallest (``"min"``: every
        fingertip must agree, as when the object slides past both gels), or the first
        fingertip's (``"first"``)."""
        tips = list(trial.values())
        if self.fingers == "first":
            tips = tips[:1]
        per = [self.finger_scores(f) for f in tips]
        n = min(len(p) for p in per)
        stacked = np.stack([p[:n] for p in per])
        out = np.full(n, np.nan)
        if self.fingers == "min":
            ok = np.isfinite(stacked).all(axis=0)
            out[ok] = np.min(stacked[:, ok], axis=0)
        else:
            ok = np.isfinite(stacked).any(axis=0)
            out[ok] = np.nanmax(stacked[:, ok], axis=0)
        if self.horizon is not None:
            out[self.arm + self.horizon :] = np.nan
        return out

    def trial_score(self, trial: Trial) -> float:
        s = self.frame_scores(trial)
        return float(np.nanmax(s)) if np.isfinite(s).any() else -np.inf

    def alarm(self, trial: Trial) -> int | None:
        return first_alarm(self.frame_scores(trial), self.threshold_)


class PinMotionDetector(_Detector):
    """Analytic: ``quantity`` of the pin field over the window (see the module doc)."""

    QUANTITIES = (
        "divergence",
        "contraction",
        "steady",
        "residual",
        "divergence_per_path",
    )

    def __init__(
        self,
        *,
        quantity: str = "divergence",
        window: int = 50,
        arm: int = 12,
        horizon: int | None = None,
        fingers: str = "max",
    ):
        super().__init__(window=window, arm=arm, horizon=horizon, fingers=fingers)
        if quantity not in self.QUANTITIES:
            raise SlipkitError(
                f"quantity={quantity!r}: expected one of {self.QUANTITIES}"
            )
        self.quantity = quantity

    def finger_scores(self, frames: FloatArray) -> FloatArray:
        f = self._features(frames)
        col = {n: f[:, i] for i, n in enumerate(FEATURES)}
        if self.quantity == "divergence":
            return np.abs(col["divergence"])
        if self.quantity == "contraction":
            return -col["divergence"]
        if self.quantity == "steady":
            return col["translation"] * col["straightness"]
        if self.quantity == "divergence_per_path":
            return np.abs(col["divergence"]) / np.maximum(col["path"], MIN_PATH)
        return col["residual"]


def model_inputs(f: FloatArray) -> FloatArray:
    """Window features as a model reads them: signed ones as they are and their
    magnitudes, the others ``log1p`` (heavy-tailed, >= 0)."""
    cols = []
    for i, name in enumerate(FEATURES):
        if name in _SIGNED:
            cols += [f[:, i], np.log1p(np.abs(f[:, i]) * 100)]
        else:
            cols.append(np.log1p(np.abs(f[:, i]) * 100))
    return np.column_stack(cols)


def _frame_weights(lengths: Sequence[int], y: Sequence[int]) -> FloatArray:
    """Each trial-fingertip counts once, each class half."""
    yy = np.asarray(y)
    per_class = {c: max(int((yy == c).sum()), 1) for c in (0, 1)}
    return np.concatenate(
        [
            np.full(n, 1.0 / (max(n, 1) * per_class[int(c)]))
            for n, c in zip(lengths, yy, strict=True)
        ]
    )


class WindowModelDetector(_Detector):
    """Logistic regression (``model="logistic"``) or RBF SVM on window features."""

    def __init__(
        self,
        *,
        model: str = "logistic",
        C: float = 1.0,
        window: int = 50,
        arm: int = 12,
        step: int = 5,
        top: float = 1.0,
        seed: int = 0,
        horizon: int | None = None,
    ):
        super().__init__(window=window, arm=arm, horizon=horizon)
        self.top = float(top)
        if model not in ("logistic", "svm"):
            raise SlipkitError(f"model={model!r}: expected 'logistic' or 'svm'")
        self.model, self.C, self.step, self.seed = model, float(C), int(step), int(seed)

    def _rows(self, frames: FloatArray) -> FloatArray:
        return model_inputs(self._features(frames))

    def fit(self, trials: Sequence[Trial], y: Sequence[int]) -> WindowModelDetector:
        xs, lens, ys = [], [], []
        for trial, label in zip(trials, y, strict=True):
            for frames in trial.values():
                r = self._rows(frames)
                r = r[np.isfinite(r).all(axis=1)][:: self.step]
                xs.append(r)
                lens.append(len(r))
                ys.append(int(label))
        X = np.concatenate(xs)
        yy = np.repeat(ys, lens)
        w = _frame_weights(lens, ys)
        w = w / w.mean()
        est = (
            LogisticRegression(C=self.C, max_iter=2000)
            if self.model == "logistic"
            else SVC(C=self.C, kernel="rbf", gamma="scale", random_state=self.seed)
        )
        self.pipeline_ = make_pipeline(StandardScaler(), est)
        name = self.pipeline_.steps[-1][0]
        self.pipeline_.fit(X, yy, **{f"{name}__sample_weight": w})
        if self.top < 1.0:
            # multiple-instance refit: a slip trial need not slip in every frame, and the
            # trial fires on its highest frame, so keep as positives only each slip
            # trial's `top` share of highest-scoring frames (every wiggle frame stays)
            s = self.pipeline_.decision_function(X)
            keep = np.ones(len(X), dtype=bool)
            start = 0
            for n, label in zip(lens, ys, strict=True):
                if label == 1 and n:
                    seg = s[start : start + n]
                    cut = np.quantile(seg, 1.0 - self.top)
                    keep[start : start + n] = seg >= cut
                start += n
            lens2 = [
                int(keep[a : a + n].sum())
                for a, n in zip(np.cumsum([0, *lens[:-1]]), lens, strict=True)
            ]
            w2 = _frame_weights(lens2, ys)
            w2 = w2 / w2.mean()
            self.pipeline_.fit(X[keep], yy[keep], **{f"{name}__sample_weight": w2})
        return self

    def finger_scores(self, frames: FloatArray) -> FloatArray:
        r = self._rows(frames)
        out = np.full(len(r), np.nan)
        ok = np.isfinite(r).all(axis=1)
        if ok.any():
            out[ok] = self.pipeline_.decision_function(r[ok])
        return out


class TacTipVelocityDetector(_Detector):
    """The TacTip paper's Gaussian SVM on pin-velocity features, averaged over ``smooth``
    frames (pin velocities in marker pitches per frame; pooled so any pin count works)."""

    def __init__(
        self,
        *,
        C: float = 1.0,
        smooth: int = 10,
        arm: int = 12,
        step: int = 5,
        seed: int = 0,
    ):
        super().__init__(window=max(2, int(smooth)), arm=arm)
        self.C, self.smooth, self.step, self.seed = (
            float(C),
            int(smooth),
            int(step),
            int(seed),
        )

    def _rows(self, frames: FloatArray) -> FloatArray:
        """Per-pin dr/dtheta velocity rows (NaN before the detector is armed + 1)."""
        pts = to_points(frames)
        rows = np.full((len(pts), pts.shape[1] * 2), np.nan)
        if len(pts) <= self.arm + 1:
            return rows
        p = pts[self.arm :] / pitch_of(pts[self.arm])
        rows[self.arm + 1 :] = velocity_features(np.diff(p, axis=0))
        return rows

    def fit(self, trials: Sequence[Trial], y: Sequence[int]) -> TacTipVelocityDetector:
        xs, lens, ys = [], [], []
        for trial, label in zip(trials, y, strict=True):
            for frames in trial.values():
                r = self._rows(frames)
                r = r[np.isfinite(r).all(axis=1)][:: self.step]
                xs.append(r)
                lens.append(len(r))
                ys.append(int(label))
        # TacTipSVM takes class weights, not sample weights: balance the classes; the
        # trials of one class are weighted by their frame counts
        self.svm_ = TacTipSVM(
            kernel="rbf",
            C=self.C,
            gamma="scale",
            standardize=True,
            class_weight="balanced",
            features="pooled",
            random_state=self.seed,
        )
        self.svm_.fit(np.concatenate(xs), np.repeat(ys, lens))
        return self

    def finger_scores(self, frames: FloatArray) -> FloatArray:
        r = self._rows(frames)
        out = np.full(len(r), np.nan)
        ok = np.isfinite(r).all(axis=1)
        if not ok.any():
            return out
        d = np.full(len(r), np.nan)
        d[ok] = self.svm_.decision_function(r[ok])
        k = self.smooth
        for t in np.flatnonzero(ok):
            seg = d[max(0, t - k + 1) : t + 1]
            if np.isfinite(seg).sum() >= min(k, 3):
                out[t] = np.nanmean(seg)
        return out


class ClipLengthControl(_Detector):
    """Control: slip when the clip is short (score = minus its frame count)."""

    streaming = False

    def frame_scores(self, trial: Trial) -> FloatArray:
        n = max(len(f) for f in trial.values())
        return np.full(n, -float(n))

    def alarm(self, trial: Trial) -> int | None:
        s = self.frame_scores(trial)
        return len(s) - 1 if s[0] >= self.threshold_ else None


class FirstFramesControl(_Detector):
    """Control: logistic regression on the features of the first ``arm`` frames only."""

    streaming = False

    def _first(self, trial: Trial) -> FloatArray:
        parts = []
        for frames in trial.values():
            f = trial_features(np.asarray(frames)[: self.arm], window=self.arm, arm=0)
            parts.append(model_inputs(f[-1:])[0])
        return np.nan_to_num(np.max(np.stack(parts), axis=0))

    def fit(self, trials: Sequence[Trial], y: Sequence[int]) -> FirstFramesControl:
        X = np.stack([self._first(t) for t in trials])
        self.pipeline_ = make_pipeline(
            StandardScaler(), LogisticRegression(class_weight="balanced", max_iter=2000)
        )
        self.pipeline_.fit(X, np.asarray(y, dtype=int))
        return self

    def frame_scores(self, trial: Trial) -> FloatArray:
        n = max(len(f) for f in trial.values())
        s = float(self.pipeline_.decision_function(self._first(trial)[None])[0])
        out = np.full(n, np.nan)
        out[min(self.arm, n) - 1] = s
        return out


class MajorityControl(_Detector):
    """Control: the training side's majority class for every trial."""

    streaming = False

    def fit(self, trials: Sequence[Trial], y: Sequence[int]) -> MajorityControl:
        self.majority_ = int(np.mean(np.asarray(y)) > 0.5)
        return self

    def frame_scores(self, trial: Trial) -> FloatArray:
        n = max(len(f) for f in trial.values())
        return np.full(n, float(self.majority_))


DETECTORS: dict[str, type[Any]] = {
    "pin_motion": PinMotionDetector,
    "window_logistic": WindowModelDetector,
    "tactip_svm": TacTipVelocityDetector,
    "clip_length": ClipLengthControl,
    "first_frames": FirstFramesControl,
    "majority": MajorityControl,
}

__all__ = [
    "DETECTORS",
    "ClipLengthControl",
    "FirstFramesControl",
    "MajorityControl",
    "PinMotionDetector",
    "TacTipVelocityDetector",
    "WindowModelDetector",
    "choose_threshold",
    "first_alarm",
    "model_inputs",
]
