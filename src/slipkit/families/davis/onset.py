"""DAVIS incipient-slip onset rule: short frames, a thin one-sided loss of contact.

Incipient slip shrinks the contact from its trailing side: the cut across the patch
moves, so the pixels that lose contact in a short frame (positive events) lie on a
straight strip about one pixel wide, and almost none gain contact (negative events).
A vibration incident shifts or dilates the whole patch: pixels lose contact around the
rim (a ring or a crescent, curved) and usually gain it elsewhere.
Pressing only gains contact. :class:`DavisOnset` reads each ``frame_s`` (5 ms) event
frame as per-pixel counts, positive then negative (the runtime's frame), and computes
(:func:`onset_features`):

- the pixels that fired with at least ``min_neighbours`` of their 8 neighbours firing
  too, per polarity (drops the sensor's isolated background events; a sum over the
  3 x 3 neighbourhood, which ONNX computes as a ``Conv``, unlike the polarity rule's
  connected components): ``pos_px``, ``neg_px``;
- ``curl``: ``12 sqrt(det C) / pos_px`` with ``C`` the kept positive pixels'
  covariance (px^2): the area of the rectangle with their second moments over their
  own area; 1 for a straight filled strip of any width, 0 for a one-pixel line, about
  ``r / t`` for a ring of radius ``r`` and width ``t`` (a curved rim).

Slip when ``pos_px >= min_pos_px``, ``neg_px <= neg_ratio pos_px`` and
``curl < max_curl`` (:func:`onset_score` > 0). Persistence (a loss that
lasts) is the deployment's debounce: ``k`` consecutive slip frames
(``configs/closedloop/davis.yaml``). The exported graph
(:mod:`slipkit.families.davis.export.onset`) computes the same features and score.
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import segment_bounds
from slipkit.families.davis.polarity import (
    NONE,
    SLIP,
    VIBRATION,
    DavisPolarity,
    FrameResult,
)

FloatArray = NDArray[np.float64]

#: columns of :func:`onset_features`
FEATURES = ("pos_px", "neg_px", "curl")
#: the 8-neighbourhood (the centre pixel not counted)
NEIGHBOURS = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], dtype=np.float64)


def kept_pixels(frames: ArrayLike, min_neighbours: int) -> NDArray[np.bool_]:
    """Pixels that fired with at least ``min_neighbours`` fired 8-neighbours, per polarity.

    ``frames``: counts ``(n, 2, H, W)``; returns a bool array of the same shape.
    """
    fired = np.asarray(frames, dtype=np.float64) > 0
    kernel = NEIGHBOURS[None, None]
    count = ndimage.convolve(fired.astype(np.float64), kernel, mode="constant")
    out: NDArray[np.bool_] = fired & (count >= min_neighbours)
    return out


def onset_features(frames: ArrayLike, *, min_neighbours: int = 2) -> FloatArray:
    """:data:`FEATURES` of event frames ``(n, 2, H, W)`` (counts per pixel) -> ``(n, 3)``."""
    f = np.asarray(frames, dtype=np.float64)
    if f.ndim != 4 or f.shape[1] != 2:
        raise ValueError(
            f"event frames must have shape (n, 2, height, width); got {f.shape}"
        )
    keep = kept_pixels(f, min_neighbours).astype(np.float64)
    areas = keep.sum(axis=(2, 3))
    pos = keep[:, 0]
    x = np.arange(f.shape[3], dtype=np.float64)
    y = np.arange(f.shape[2], dtype=np.float64)
    rows, cols = pos.sum(axis=2), pos.sum(axis=1)  # (n, H), (n, W)
    n = np.maximum(areas[:, 0], 1.0)
    mx, my = cols @ x / n, rows @ y / n
    vx = cols @ (x * x) / n - mx * mx
    vy = rows @ (y * y) / n - my * my
    cxy = (pos @ x) @ y / n - mx * my
    det = np.maximum(vx * vy - cxy * cxy, 0.0)
    curl = 12.0 * np.sqrt(det) / n
    return np.column_stack([areas[:, 0], areas[:, 1], curl])


def onset_score(
    features: ArrayLike,
    *,
    min_pos_px: int,
    neg_ratio: float,
    max_curl: float,
) -> FloatArray:
    """``min(pos - min_pos_px + 0.5, neg_ratio pos - neg + 0.5, max_curl - curl)``: > 0 is slip.

    Areas are whole pixels, so the first term is > 0 exactly when ``pos >= min_pos_px``
    and the second when ``neg <= neg_ratio pos`` (up to half a pixel).
    """
    a = np.asarray(features, dtype=np.float64).reshape(-1, 3)
    pos, neg, curl = a[:, 0], a[:, 1], a[:, 2]
    return np.minimum(
        np.minimum(pos - float(min_pos_px) + 0.5, float(neg_ratio) * pos - neg + 0.5),
        float(max_curl) - curl,
    )


@dataclass(frozen=True)
class OnsetFrame(FrameResult):
    """A :class:`~slipkit.families.davis.polarity.FrameResult` with the positive pixels' curl."""

    curl: float = 0.0


class DavisOnset(DavisPolarity):
    """A thin one-sided loss of contact on short event frames (module docstring).

    Parameters
    ----------
    frame_s : float
        Event-frame length (s; 0.005: a decision every 5 ms).
    width_px, height_px : int
        Event array size (px).
    min_neighbours : int
        Fired 8-neighbours a fired pixel needs to count (0..8).
    min_pos_px : int
        Smallest kept positive area (px) that counts as a loss of contact.
    neg_ratio : float
        Largest kept negative area per px of positive area.
    max_curl : float
        Largest curl of a slip frame's positive pixels (1: a straight strip).

    Frames with a positive area that fail the rule are ``VIBRATION`` in
    :meth:`frames` (code 1), as in the polarity rule; ``pos_area_px`` and
    ``neg_area_px`` are the kept areas.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "frame_s": [Interval(Real, 0, None, closed="neither")],
        "width_px": [Interval(Integral, 1, None, closed="left")],
        "height_px": [Interval(Integral, 1, None, closed="left")],
        "min_neighbours": [Interval(Integral, 0, 8, closed="both")],
        "min_pos_px": [Interval(Integral, 1, None, closed="left")],
        "neg_ratio": [Interval(Real, 0, None, closed="left")],
        "max_curl": [Interval(Real, 0, None, closed="neither")],
    }

    def __init__(
        self,
        *,
        frame_s: float = 0.005,
        width_px: int = 190,
        height_px: int = 180,
        min_neighbours: int = 1,
        min_pos_px: int = 3,
        neg_ratio: float = 0.25,
        max_curl: float = 5.0,
    ) -> None:
        self.frame_s = frame_s
        self.width_px = width_px
        self.height_px = height_px
        self.min_neighbours = min_neighbours
        self.min_pos_px = min_pos_px
        self.neg_ratio = neg_ratio
        self.max_curl = max_curl

    def features(self, frames: ArrayLike) -> FloatArray:
        """:func:`onset_features` of event frames ``(n, 2, H, W)``."""
        return onset_features(frames, min_neighbours=int(self.min_neighbours))

    def score(self, features: ArrayLike) -> FloatArray:
        """:func:`onset_score` with this detector's parameters."""
        return onset_score(
            features,
            min_pos_px=int(self.min_pos_px),
            neg_ratio=float(self.neg_ratio),
            max_curl=float(self.max_curl),
        )

    def _result(self, f: int, chunk: FloatArray, stress: FloatArray) -> FrameResult:
        frame = np.zeros((1, 2, int(self.height_px), int(self.width_px)))
        if len(chunk):
            ch = (chunk[:, 3] < 0).astype(np.intp)
            y, x = chunk[:, 2].astype(np.intp), chunk[:, 1].astype(np.intp)
            np.add.at(frame[0], (ch, y, x), 1)
            stress += kept_pixels(frame, int(self.min_neighbours))[0, 1]
        feats = self.features(frame)
        pos, neg, curl = feats[0]
        slip = bool(self.score(feats)[0] > 0)
        return OnsetFrame(
            frame=f,
            t_start_s=f * float(self.frame_s),
            t_end_s=(f + 1) * float(self.frame_s),
            pos_area_px=int(pos),
            neg_area_px=int(neg),
            incident=SLIP if slip else (VIBRATION if pos > 0 else NONE),
            curl=float(curl),
        )

    def frames(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> pd.DataFrame:
        """Per-frame table as :meth:`DavisPolarity.frames`, with ``curl``."""
        check_is_fitted(self, "classes_")
        ev = self.check_events(X)
        rows: list[dict[str, Any]] = []
        for s, (a, b) in enumerate(segment_bounds(len(ev), segments)):
            results, _ = self._recording(ev[a:b])
            rows.extend({"segment": s, **r.__dict__, "slip": r.slip} for r in results)
        cols = ["segment", "frame", "t_start_s", "t_end_s", "pos_area_px"]
        cols += ["neg_area_px", "curl", "incident", "slip"]
        return pd.DataFrame(rows, columns=cols)


__all__ = [
    "FEATURES",
    "DavisOnset",
    "OnsetFrame",
    "kept_pixels",
    "onset_features",
    "onset_score",
]
