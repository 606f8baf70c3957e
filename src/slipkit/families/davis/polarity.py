"""DAVIS event-polarity incipient slip detector (Rigi et al. 2018, Sensors 18(2):333).

The paper's algorithm (Sec. 3, pseudo-code), ``docs/families/davis.md``:

1. every ``frame_s`` = 10 ms, the events of that window become a positive and a negative
   binary frame (pixel set when it fired at least one event of that polarity);
2. each frame is cleaned by a morphological opening then a closing
   (``scipy.ndimage.binary_opening`` / ``binary_closing``) and an area filter that keeps
   the connected regions (``scipy.ndimage.label``, 8-connected) of at least
   ``min_area_px`` pixels;
3. an *incident* exists when the positive area is > 0: **slip** when positive area >=
   negative area, else **vibration**;
4. the negative regions are the contact area; accumulated over frames they form the
   stress map.

Input. Events are not a sampled stream, so ``X`` is the event table: one row per event,
columns ``(t, x, y, polarity)`` (s, px, px, +1/-1), in time order, with optional
``segments`` (one recording id per event). Frame ``k`` of a recording holds the events
with ``k frame_s <= t < (k + 1) frame_s`` (an absolute grid from t = 0, so every event's
frame is known without the rest of the recording). :meth:`DavisPolarity.frames` gives the
per-frame table (areas, incident, slip); :meth:`DavisPolarity.predict` gives each event its
frame's slip decision (a frame without events has no positive area, hence no slip, so
nothing is lost). The streaming form (:meth:`DavisPolarity.stream`) takes events (any
chunk, in time order) or one frame at a time and emits each frame once it is complete.

Scoring (Sec. 4.4) lives here too: :func:`bin_scores` splits a trial into 20 ms bins and
counts TP / FP / FN (TN ignored) and the latency from the incipient-slip onset to the
first true-positive detection.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import segment_bounds

FloatArray = NDArray[np.float64]
BoolImage = NDArray[np.bool_]

#: incident codes of :meth:`DavisPolarity.frames`
NONE, VIBRATION, SLIP = 0, 1, 2
#: 8-connectivity for region labelling (a diagonal neighbour joins a region)
EIGHT = np.ones((3, 3), dtype=bool)


# -- one frame ------------------------------------------------------------------------------
def clean_frame(
    frame: BoolImage,
    *,
    opening_px: int,
    closing_px: int,
    min_area_px: int,
    opening_shape: str = "square",
) -> BoolImage:
    """Opening, closing and area filter of one binary event frame (paper Sec. 3.1).

    Parameters
    ----------
    frame : ndarray of bool (height, width)
        Pixels that fired in the window.
    opening_px, closing_px : int
        Side of the square structuring element of the opening / closing (px; 1 or 0:
        skip the operation).
    opening_shape : {"square", "lines"}
        ``square``: one opening with an ``opening_px`` square; ``lines``: the union of the
        openings with a horizontal and a vertical line of ``opening_px`` pixels, which
        removes isolated pixels but keeps 1-pixel-wide edges (a slow release uncovers a
        strip about one pixel wide per 10 ms frame, which a square opening erases).
    min_area_px : int
        Smallest connected region kept (px; the paper: "resolution 8 pixels").

    Returns
    -------
    ndarray of bool
        The kept regions.
    """
    img = np.asarray(frame, dtype=bool)
    if not img.any():
        return img
    if opening_px > 1:
        # border_value 0 (scipy's default): a region touching the edge erodes there too.
        if opening_shape == "square":
            img = ndimage.binary_opening(
                img, structure=np.ones((opening_px, opening_px))
            )
        elif opening_shape == "lines":
            line = np.ones((1, opening_px), dtype=bool)
            img = ndimage.binary_opening(img, structure=line) | ndimage.binary_opening(
                img, structure=line.T
            )
        else:
            raise ValueError(
                f"opening_shape must be 'square' or 'lines'; got {opening_shape!r}"
            )
    if closing_px > 1 and img.any():
        # Closing only on the bounding box of the set pixels, padded so the dilation
        # never meets the border (a closing can only add pixels within closing_px of a
        # set one): the same result as on the whole frame, far cheaper.
        pad = closing_px
        rows, cols = np.flatnonzero(img.any(axis=1)), np.flatnonzero(img.any(axis=0))
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        box = np.pad(img[r0:r1, c0:c1], pad)
        box = ndimage.binary_closing(box, structure=np.ones((closing_px, closing_px)))
        img = img.copy()
        img[r0:r1, c0:c1] = box[pad:-pad, pad:-pad]
    if min_area_px > 1 and img.any():
        labels, n = ndimage.label(img, structure=EIGHT)
        if n:
            sizes = np.bincount(labels.ravel(), minlength=n + 1)
            keep = sizes >= min_area_px
            keep[0] = False
            img = keep[labels]
    return img


def classify(pos_area: ArrayLike, neg_area: ArrayLike) -> NDArray[np.int_]:
    """Incident per frame (paper Sec. 3.2): 0 none, 1 vibration, 2 slip.

    An incident exists when the positive area is > 0; slip when positive area >=
    negative area, vibration otherwise.
    """
    pos = np.asarray(pos_area)
    neg = np.asarray(neg_area)
    return np.where(pos > 0, np.where(pos >= neg, SLIP, VIBRATION), NONE).astype(int)


@dataclass(frozen=True)
class FrameResult:
    """One 10 ms frame's outcome.

    Attributes
    ----------
    frame : int
        Frame index ``k`` (the window ``[k frame_s, (k + 1) frame_s)``).
    t_start_s, t_end_s : float
        Window bounds (s); the decision is available at ``t_end_s``.
    pos_area_px, neg_area_px : int
        Areas left after filtering (px).
    incident : int
        0 none, 1 vibration, 2 slip.
    """

    frame: int
    t_start_s: float
    t_end_s: float
    pos_area_px: int
    neg_area_px: int
    incident: int

    @property
    def slip(self) -> bool:
        """The slip decision."""
        return self.incident == SLIP


# -- estimator -------------------------------------------------------------------------------
class DavisPolarity(ClassifierMixin, BaseEstimator):
    """Rigi et al.'s event-polarity slip / vibration detector on 10 ms event frames.

    ``fit`` learns nothing (the paper's rule has no threshold to choose): it checks the
    parameters and records the channel count. See the module docstring for ``X``.

    Parameters
    ----------
    frame_s : float
        Event-frame length (s; the paper: 0.01).
    width_px, height_px : int
        Event array size (px; the paper: 190 x 180).
    opening_px, closing_px : int
        Structuring elements of the opening and closing (px).
    opening_shape : {"square", "lines"}
        Opening element: an ``opening_px`` square, or the union of the openings with
        horizontal and vertical ``opening_px`` lines (see :func:`clean_frame`).
    min_area_px : int
        Area filter: smallest connected region kept (px; the paper: 8).

    Attributes
    ----------
    classes_ : ndarray
        ``[0, 1]`` (1 = slip).
    n_features_in_ : int
        4 (t, x, y, polarity).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "frame_s": [Interval(Real, 0, None, closed="neither")],
        "width_px": [Interval(Integral, 1, None, closed="left")],
        "height_px": [Interval(Integral, 1, None, closed="left")],
        "opening_px": [Interval(Integral, 0, None, closed="left")],
        "opening_shape": [StrOptions({"square", "lines"})],
        "closing_px": [Interval(Integral, 0, None, closed="left")],
        "min_area_px": [Interval(Integral, 0, None, closed="left")],
    }

    def __init__(
        self,
        *,
        frame_s: float = 0.01,
        width_px: int = 190,
        height_px: int = 180,
        opening_px: int = 2,
        opening_shape: str = "lines",
        closing_px: int = 3,
        min_area_px: int = 8,
    ) -> None:
        self.frame_s = frame_s
        self.width_px = width_px
        self.height_px = height_px
        self.opening_px = opening_px
        self.opening_shape = opening_shape
        self.closing_px = closing_px
        self.min_area_px = min_area_px

    # -- input -------------------------------------------------------------------------
    def check_events(self, X: ArrayLike) -> FloatArray:
        """``X`` as a float (n_events, 4) array, checked: finite, in the array, +-1, sorted."""
        if isinstance(X, pd.DataFrame):
            missing = [c for c in ("t", "x", "y", "polarity") if c not in X.columns]
            if missing:
                raise ValueError(f"event table lacks columns {missing}")
            X = X[["t", "x", "y", "polarity"]].to_numpy(dtype=np.float64)
        ev = np.asarray(X, dtype=np.float64)
        if ev.ndim != 2 or ev.shape[1] != 4:
            raise ValueError(
                f"events must be an (n_events, 4) table of (t, x, y, polarity); got shape "
                f"{ev.shape}"
            )
        if len(ev) == 0:
            return ev.reshape(0, 4)
        if not np.isfinite(ev).all():
            raise ValueError("events hold NaN or inf values")
        x, y, p = ev[:, 1], ev[:, 2], ev[:, 3]
        if (x < 0).any() or (x >= self.width_px).any() or (x != np.round(x)).any():
            raise ValueError(f"event x must be integer pixels in [0, {self.width_px})")
        if (y < 0).any() or (y >= self.height_px).any() or (y != np.round(y)).any():
            raise ValueError(f"event y must be integer pixels in [0, {self.height_px})")
        if not np.isin(p, (-1.0, 1.0)).all():
            raise ValueError("event polarity must be +1 or -1")
        if (ev[:, 0] < 0).any():
            raise ValueError("event t must be >= 0 s (the frame grid starts at t = 0)")
        return ev

    def _frame_of(self, t: FloatArray) -> NDArray[np.int64]:
        return np.floor(t / self.frame_s).astype(np.int64)

    def _frame_areas(self, ev: FloatArray) -> tuple[int, int, BoolImage]:
        """Filtered positive and negative areas of one frame's events; the negative mask."""
        shape = (int(self.height_px), int(self.width_px))
        out = []
        for sign in (1.0, -1.0):
            sel = ev[ev[:, 3] == sign]
            img = np.zeros(shape, dtype=bool)
            img[sel[:, 2].astype(int), sel[:, 1].astype(int)] = True
            out.append(
                clean_frame(
                    img,
                    opening_px=int(self.opening_px),
                    closing_px=int(self.closing_px),
                    min_area_px=int(self.min_area_px),
                    opening_shape=str(self.opening_shape),
                )
            )
        return int(out[0].sum()), int(out[1].sum()), out[1]

    def _recording(self, ev: FloatArray) -> tuple[list[FrameResult], FloatArray]:
        """Frame results (frame 0 to the last event's frame) and the stress map."""
        stress = np.zeros((int(self.height_px), int(self.width_px)))
        if len(ev) == 0:
            return [], stress
        if (np.diff(ev[:, 0]) < 0).any():
            raise ValueError("events must be in time order (t non-decreasing)")
        k = self._frame_of(ev[:, 0])
        n = int(k[-1]) + 1
        starts = np.searchsorted(k, np.arange(n + 1), side="left")
        results = []
        for f in range(n):
            chunk = ev[starts[f] : starts[f + 1]]
            results.append(self._result(f, chunk, stress))
        return results, stress

    def _result(self, f: int, chunk: FloatArray, stress: FloatArray) -> FrameResult:
        if len(chunk):
            pos, neg, neg_mask = self._frame_areas(chunk)
            stress += neg_mask  # the paper: stressMap <- previous + negFrameArea
        else:
            pos, neg = 0, 0
        return FrameResult(
            frame=f,
            t_start_s=f * float(self.frame_s),
            t_end_s=(f + 1) * float(self.frame_s),
            pos_area_px=pos,
            neg_area_px=neg,
            incident=int(classify(pos, neg)),
        )

    # -- sklearn ------------------------------------------------------------------------
    def fit(
        self,
        X: ArrayLike,
        y: ArrayLike | None = None,
        *,
        segments: ArrayLike | None = None,
    ) -> DavisPolarity:
        """Check parameters and events; nothing is learned (the rule is fixed)."""
        self._validate_params()
        self.check_events(X)
        del y, segments
        self.classes_ = np.array([0, 1])
        self.n_features_in_ = 4
        return self

    def frames(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> pd.DataFrame:
        """Per-frame table of every recording (batch form).

        Columns: ``segment`` (index of the recording in order), ``frame``, ``t_start_s``,
        ``t_end_s``, ``pos_area_px``, ``neg_area_px``, ``incident`` (0/1/2), ``slip``.
        """
        check_is_fitted(self, "classes_")
        ev = self.check_events(X)
        rows: list[dict[str, Any]] = []
        for s, (a, b) in enumerate(segment_bounds(len(ev), segments)):
            results, _ = self._recording(ev[a:b])
            rows.extend({"segment": s, **r.__dict__, "slip": r.slip} for r in results)
        cols = ["segment", "frame", "t_start_s", "t_end_s", "pos_area_px"]
        cols += ["neg_area_px", "incident", "slip"]
        return pd.DataFrame(rows, columns=cols)

    def stress_map(self, X: ArrayLike) -> FloatArray:
        """Accumulated filtered negative regions of one recording (count per pixel)."""
        check_is_fitted(self, "classes_")
        return self._recording(self.check_events(X))[1]

    def predict(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> NDArray[np.int_]:
        """Per event: 1 when its 10 ms frame is classified slip, else 0."""
        check_is_fitted(self, "classes_")
        ev = self.check_events(X)
        out = np.zeros(len(ev), dtype=int)
        for a, b in segment_bounds(len(ev), segments):
            results, _ = self._recording(ev[a:b])
            if results:
                slip = np.array([r.slip for r in results])
                out[a:b] = slip[self._frame_of(ev[a:b, 0])]
        return out

    def stream(self) -> DavisStream:
        """The streaming form (frames emitted as they complete)."""
        check_is_fitted(self, "classes_")
        return DavisStream(self)


class DavisStream:
    """Streaming :class:`DavisPolarity`: events in, completed frames out.

    :meth:`push` takes any chunk of events in time order and returns the frames it
    completed (an event in frame ``k`` completes every frame before ``k``, including
    empty ones); :meth:`flush` completes the current frame; :meth:`update_frame` takes
    all events of the next frame at once. Work per frame is O(frame pixels).

    Attributes
    ----------
    stress_map : ndarray
        Accumulated filtered negative regions so far.
    contact_area_px : int
        Negative area of the last frame that had one (the paper's ``contactArea``).
    """

    def __init__(self, det: DavisPolarity) -> None:
        self.det = det
        self.reset()

    def reset(self) -> None:
        """Forget all state (a new recording starts)."""
        self.stress_map = np.zeros((int(self.det.height_px), int(self.det.width_px)))
        self.contact_area_px = 0
        self._frame = 0
        self._pending: list[FloatArray] = []
        self._last_t = -np.inf

    def _close(self) -> FrameResult:
        chunk = np.concatenate(self._pending) if self._pending else np.empty((0, 4))
        r = self.det._result(self._frame, chunk, self.stress_map)
        if r.neg_area_px > 0:
            self.contact_area_px = r.neg_area_px
        self._pending = []
        self._frame += 1
        return r

    def push(self, events: ArrayLike) -> list[FrameResult]:
        """Feed events (n, 4) in time order; return the frames they completed."""
        ev = self.det.check_events(events)
        if len(ev) == 0:
            return []
        if ev[0, 0] < self._last_t or (np.diff(ev[:, 0]) < 0).any():
            raise ValueError("events must arrive in time order (t non-decreasing)")
        self._last_t = float(ev[-1, 0])
        k = self.det._frame_of(ev[:, 0])
        frames, first = np.unique(k, return_index=True)
        bounds = [*first.tolist(), len(ev)]
        done: list[FrameResult] = []
        for i, f in enumerate(frames):
            while self._frame < f:  # this event completes the frames before it
                done.append(self._close())
            self._pending.append(ev[bounds[i] : bounds[i + 1]])
        return done

    def flush(self) -> FrameResult:
        """Complete the current frame (end of the recording) and return it."""
        return self._close()

    def update_frame(self, events: ArrayLike) -> FrameResult:
        """All events of the next frame at once; its result (events outside it: error)."""
        ev = self.det.check_events(events)
        k = self.det._frame_of(ev[:, 0])
        if len(ev) and (k != self._frame).any():
            raise ValueError(
                f"update_frame expects events of frame {self._frame} "
                f"(t in [{self._frame * self.det.frame_s:.4f}, "
                f"{(self._frame + 1) * self.det.frame_s:.4f}) s)"
            )
        self._pending.append(ev)
        return self._close()

    def feed(self, events: Iterable[ArrayLike]) -> list[FrameResult]:
        """Push every chunk, then flush: the whole recording's frames."""
        out: list[FrameResult] = []
        for chunk in events:
            out.extend(self.push(chunk))
        if self._pending and sum(len(p) for p in self._pending):
            out.append(self.flush())
        return out


# -- scoring (paper Sec. 4.4) ---------------------------------------------------------------
def contact_end(t: ArrayLike, area: ArrayLike, onset_s: float) -> float:
    """First truth time at or after ``onset_s`` whose contact area is zero (s; end of
    slip), or the last truth time if contact never ends."""
    tv, av = np.asarray(t, dtype=np.float64), np.asarray(area, dtype=np.float64)
    after = np.flatnonzero((tv >= onset_s) & (av <= 0))
    return float(tv[after[0]]) if len(after) else float(tv[-1])


def bin_scores(
    slip_frames: pd.DataFrame,
    *,
    onset_s: float,
    end_s: float,
    duration_s: float,
    bin_s: float = 0.02,
) -> dict[str, Any]:
    """TP / FP / FN over ``bin_s`` bins of one trial, and the detection latency.

    Parameters
    ----------
    slip_frames : DataFrame
        Frame table with ``t_start_s``, ``t_end_s`` and ``slip`` (bool).
    onset_s, end_s : float
        Incipient slip onset and the end of contact (s): truth bins are those that
        overlap ``[onset_s, end_s)``.
    duration_s : float
        Trial length (s): bins cover ``[0, duration_s)``.
    bin_s : float
        Bin length (s; the paper: 0.02).

    Returns
    -------
    dict
        ``tp``, ``fp``, ``fn`` (TN ignored), ``latency_s`` (end of the first slip frame that
        ends after the onset and starts before ``end_s``, minus ``onset_s``: when the
        decision is available; NaN when slip is never detected).
    """
    n_bins = max(1, int(np.ceil(duration_s / bin_s - 1e-9)))
    lo = np.arange(n_bins) * bin_s
    hi = lo + bin_s
    truth = (hi > onset_s) & (lo < end_s)
    pred = np.zeros(n_bins, dtype=bool)
    slip = slip_frames[slip_frames["slip"].astype(bool)]
    if len(slip):
        # A frame marks every bin it overlaps (10 ms frames sit inside 20 ms bins).
        first = np.floor(slip["t_start_s"].to_numpy() / bin_s + 1e-9).astype(int)
        last = np.ceil(slip["t_end_s"].to_numpy() / bin_s - 1e-9).astype(int) - 1
        for a, b in zip(first, last, strict=True):
            pred[max(a, 0) : min(b, n_bins - 1) + 1] = True
    tp = int((truth & pred).sum())
    fp = int((~truth & pred).sum())
    fn = int((truth & ~pred).sum())
    hit = slip[(slip["t_end_s"] > onset_s) & (slip["t_start_s"] < end_s)]
    latency = float(hit["t_end_s"].min() - onset_s) if len(hit) else float("nan")
    return {"tp": tp, "fp": fp, "fn": fn, "latency_s": latency}


def prf(tp: int, fp: int, fn: int) -> dict[str, float]:
    """Precision, sensitivity and F1 (paper eqs. 1-3); NaN where undefined."""
    nan = float("nan")
    return {
        "precision": tp / (tp + fp) if tp + fp else nan,
        "sensitivity": tp / (tp + fn) if tp + fn else nan,
        "f1": 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else nan,
    }


__all__ = [
    "NONE",
    "SLIP",
    "VIBRATION",
    "DavisPolarity",
    "DavisStream",
    "FrameResult",
    "bin_scores",
    "classify",
    "clean_frame",
    "contact_end",
    "prf",
]
