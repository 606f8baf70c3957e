"""A learned DAVIS slip classifier on event-frame features.

Rigi et al.'s rule (:class:`slipkit.families.davis.polarity.DavisPolarity`) cleans each event
frame morphologically and calls slip when the positive (contact lost) area dominates.
:class:`EventFrameClassifier` learns the same decision from labelled frames instead:
per ``frame_s`` frame (20 ms, the scoring bin) of one recording it counts

* positive and negative events (``log1p`` of each),
* the positive and negative areas: distinct pixels that fired (``log1p``, px),
* the positive share of the events and of the area (``(p + 1) / (p + n + 2)``),

standardises them and fits a logistic regression; a frame is slip when its probability
reaches 1/2 (class-balanced weights). The labels come from the task: a frame is slip
when it overlaps ``[onset, end of contact)`` of its recording (the task's scoring
truth), so ``fit`` needs ``onsets`` and ``ends`` per recording
(:class:`~slipkit.families.davis.task.DavisRelease` passes them to an estimator whose
``fit`` takes them). No morphology: the background events the rule's opening removes
are left to the weights (a uniform background raises both counts, the slip's edge
only the positive one).

``frames`` returns the rule's frame table (``segment, frame, t_start_s, t_end_s,
pos_area_px, neg_area_px, incident, slip``), so the DAVIS task scores both the same way.
Exported by :mod:`slipkit.families.davis.export.classifier`: the features from the runtime's event frames
(counts per pixel) as ONNX ops, the scaler and logistic regression through skl2onnx.
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import segment_bounds
from slipkit.errors import SlipkitError
from slipkit.families.davis.polarity import NONE, SLIP, DavisPolarity

#: feature names, in column order
FEATURES = (
    "log_pos_events",
    "log_neg_events",
    "log_pos_area_px",
    "log_neg_area_px",
    "pos_event_share",
    "pos_area_share",
)


def event_features(
    counts: NDArray[np.float64], areas: NDArray[np.float64]
) -> NDArray[np.float64]:
    """:data:`FEATURES` of frames from their event counts and areas.

    Parameters
    ----------
    counts, areas : ndarray of shape (n_frames, 2)
        Positive and negative events per frame, and the distinct pixels (px) each
        polarity fired. The exported graph (:mod:`slipkit.families.davis.export.classifier`) computes
        the same numbers from the runtime's event frames.

    Returns
    -------
    ndarray of shape (n_frames, len(FEATURES))
    """
    return np.column_stack(
        [
            np.log1p(counts),
            np.log1p(areas),
            (counts[:, 0] + 1) / (counts.sum(axis=1) + 2),
            (areas[:, 0] + 1) / (areas.sum(axis=1) + 2),
        ]
    )


class EventFrameClassifier(ClassifierMixin, BaseEstimator):
    """Slip per event frame from polarity counts and areas -> logistic regression.

    Parameters
    ----------
    frame_s : float
        Frame length (s; 0.02 = the DAVIS task's scoring bin).
    width_px, height_px : int
        Event array size (px).
    C : float
        Inverse L2 strength of the logistic regression.
    class_weight : {"balanced"} or None
        Class weights of the logistic regression.

    Attributes
    ----------
    classes_ : ndarray
        ``[0, 1]`` (1 = slip).
    pipeline_ : Pipeline
        ``StandardScaler`` -> ``LogisticRegression`` on :data:`FEATURES`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "frame_s": [Interval(Real, 0, None, closed="neither")],
        "width_px": [Interval(Integral, 1, None, closed="left")],
        "height_px": [Interval(Integral, 1, None, closed="left")],
        "C": [Interval(Real, 0, None, closed="neither")],
        "class_weight": [StrOptions({"balanced"}), None],
    }

    def __init__(
        self,
        *,
        frame_s: float = 0.02,
        width_px: int = 190,
        height_px: int = 180,
        C: float = 1.0,
        class_weight: str | None = "balanced",
    ) -> None:
        self.frame_s = frame_s
        self.width_px = width_px
        self.height_px = height_px
        self.C = C
        self.class_weight = class_weight

    def _check(self, X: ArrayLike) -> NDArray[np.float64]:
        # The rule's checks (columns, pixels in the array, polarity +-1, t >= 0).
        return DavisPolarity(
            width_px=int(self.width_px), height_px=int(self.height_px)
        ).check_events(X)

    def frame_features(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> tuple[pd.DataFrame, NDArray[np.float64]]:
        """Frames of every recording (frame 0 to its last event's) and their features.

        Returns
        -------
        frames : DataFrame
            ``segment, frame, t_start_s, t_end_s, pos_area_px, neg_area_px``.
        F : ndarray of shape (n_frames, len(FEATURES))
        """
        ev = self._check(X)
        rows: list[pd.DataFrame] = []
        feats: list[NDArray[np.float64]] = []
        w = int(self.width_px)
        for s, (a, b) in enumerate(segment_bounds(len(ev), segments)):
            e = ev[a:b]
            if len(e) == 0:
                continue
            if (np.diff(e[:, 0]) < 0).any():
                raise SlipkitError(
                    f"recording {s}: events must be in time order (t non-decreasing)"
                )
            k = np.floor(e[:, 0] / float(self.frame_s)).astype(np.int64)
            n = int(k[-1]) + 1
            counts = np.zeros((n, 2))
            areas = np.zeros((n, 2))
            for j, sign in enumerate((1.0, -1.0)):
                sel = e[:, 3] == sign
                counts[:, j] = np.bincount(k[sel], minlength=n)
                pix = k[sel] * (w * int(self.height_px)) + (
                    e[sel, 2].astype(np.int64) * w + e[sel, 1].astype(np.int64)
                )
                uniq = np.unique(pix) // (w * int(self.height_px))
                areas[:, j] = np.bincount(uniq, minlength=n)
            f = event_features(counts, areas)
            idx = np.arange(n)
            rows.append(
                pd.DataFrame(
                    {
                        "segment": s,
                        "frame": idx,
                        "t_start_s": idx * float(self.frame_s),
                        "t_end_s": (idx + 1) * float(self.frame_s),
                        "pos_area_px": areas[:, 0].astype(int),
                        "neg_area_px": areas[:, 1].astype(int),
                    }
                )
            )
            feats.append(f)
        cols = ["segment", "frame", "t_start_s", "t_end_s", "pos_area_px"]
        frames = (
            pd.concat(rows, ignore_index=True)
            if rows
            else pd.DataFrame(columns=[*cols, "neg_area_px"])
        )
        F = np.concatenate(feats) if feats else np.empty((0, len(FEATURES)))
        return frames, F

    def fit(
        self,
        X: ArrayLike,
        y: ArrayLike | None = None,
        *,
        segments: ArrayLike | None = None,
        onsets: ArrayLike | None = None,
        ends: ArrayLike | None = None,
    ) -> EventFrameClassifier:
        """Fit on the frames of labelled recordings.

        Parameters
        ----------
        X : array_like of shape (n_events, 4)
            Events ``t (s), x, y (px), polarity (+-1)`` of every recording, in order.
        y : ignored
            Labels come from ``onsets`` / ``ends``.
        segments : array_like of int, optional
            Recording index of every event (non-decreasing).
        onsets, ends : array_like of float, shape (n_recordings,)
            Slip onset and end of contact per recording (s; ``inf`` for no slip).

        Raises
        ------
        SlipkitError
            Without ``onsets`` / ``ends``, or with training frames of one class only.
        """
        self._validate_params()
        del y
        if onsets is None or ends is None:
            raise SlipkitError(
                "EventFrameClassifier.fit needs onsets= and ends= per recording "
                "(the DAVIS task passes them)"
            )
        frames, F = self.frame_features(X, segments=segments)
        on = np.asarray(onsets, dtype=np.float64)[frames["segment"].to_numpy(int)]
        end = np.asarray(ends, dtype=np.float64)[frames["segment"].to_numpy(int)]
        label = (
            (frames["t_end_s"].to_numpy() > on) & (frames["t_start_s"].to_numpy() < end)
        ).astype(int)
        if len(np.unique(label)) < 2:
            raise SlipkitError(
                "EventFrameClassifier.fit: the training frames need slip and non-slip "
                "frames"
            )
        self.pipeline_: Pipeline = make_pipeline(
            StandardScaler(),
            LogisticRegression(C=float(self.C), class_weight=self.class_weight),
        ).fit(F, label)
        self.classes_ = np.array([0, 1])
        self.n_features_in_ = 4
        return self

    def predict_proba_frames(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> tuple[pd.DataFrame, NDArray[np.float64]]:
        """Frames and each one's slip probability."""
        check_is_fitted(self, "pipeline_")
        frames, F = self.frame_features(X, segments=segments)
        p = self.pipeline_.predict_proba(F)[:, 1] if len(F) else np.empty(0)
        return frames, p

    def frames(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> pd.DataFrame:
        """The rule's frame table (batch form); ``slip`` where the probability >= 1/2."""
        frames, p = self.predict_proba_frames(X, segments=segments)
        slip = p >= 0.5
        return frames.assign(incident=np.where(slip, SLIP, NONE).astype(int), slip=slip)


__all__ = ["FEATURES", "EventFrameClassifier", "event_features"]
