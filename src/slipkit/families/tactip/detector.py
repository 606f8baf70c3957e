"""Analytic TacTip slip detector: pooled pin motion, any pin count.

The paper's SVM (:mod:`slipkit.models.svm`) reads one feature per pin, so it is tied to
the pin count and layout it was trained on. :class:`PinMotionDetector` reads the raw
``pins`` stream (``x0 .. x{N-1}, y0 .. y{N-1}``, mm, NaN for a pin not detected) and
reduces every frame to the *mean* pin motion over the pins that are present, so a
detector fitted on 127 pins runs unchanged on 331.

Scores (``score``), per camera frame ``t``, with ``d(a, b)`` the mean over pins of
``p_b - p_a`` (mm; a pin counts when it is finite in both frames, the NaN-robust
mean):

* ``"coherent"`` -- ``|d(t-1, t)|`` (mm/frame): the length of the mean pin velocity,
  i.e. mean speed x how aligned the pins move (pins jittering in random directions
  cancel, pins sliding together add up);
* ``"reversal"`` -- ``-d(t-1, t) . u / |u|`` (mm/frame) with ``u = d(t-gap-lookback,
  t-gap)``: the speed of the mean pin velocity *against* the mean motion of a
  ``lookback``-frame stretch that ended ``gap`` frames ago. Before a slip the skin
  stretches (and creeps, Mindlin partial slip) along the load; at the onset it snaps
  back the other way. A creep is as aligned as a slip, so ``"coherent"`` mistakes the
  last creep frames for slip; ``"reversal"`` does not. The ``gap`` keeps the first
  slip frames out of the reference, so a slip keeps scoring for ``gap`` frames.

Then ``consecutive`` frames are combined by their minimum: the score is at least the
threshold exactly when the last ``consecutive`` raw scores all are (the paper's
two-frame rule inside the detector). A frame before the first full window, or whose
velocity has no pin present in both frames, scores ``-inf``.

Both scores are in mm per *frame*: at a lower frame rate a slip moves further per
frame, so a threshold fitted at 120 FPS is conservative (fires no more often) at
60 FPS; jitter does not scale with the rate.
"""

from __future__ import annotations

from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_array

from slipkit.baselines.base import FloatArray, StreamDetector
from slipkit.baselines.generic import OnsetCalibration, RingStream

#: Smallest reference displacement (mm) the reversal divides by: below it the
#: reference has no direction and the score is 0 (no evidence of a reversal).
MIN_REFERENCE_MM = 1e-12


def mean_displacement(
    x_from: FloatArray, y_from: FloatArray, x_to: FloatArray, y_to: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Mean pin displacement between frames over the pins finite in both (mm).

    Parameters
    ----------
    x_from, y_from, x_to, y_to : ndarray of shape (..., N)
        Pin coordinates (mm) of the earlier and the later frame.

    Returns
    -------
    dx, dy : ndarray of shape (...,)
        Mean displacement, mm (0 where no pin is present in both frames).
    count : ndarray of shape (...,)
        Pins present in both frames.
    """
    dx, dy = x_to - x_from, y_to - y_from
    ok = np.isfinite(dx) & np.isfinite(dy)
    count = ok.sum(axis=-1).astype(np.float64)
    c = np.maximum(count, 1.0)
    return (
        np.where(ok, dx, 0.0).sum(axis=-1) / c,
        np.where(ok, dy, 0.0).sum(axis=-1) / c,
        count,
    )


class PinMotionDetector(OnsetCalibration, StreamDetector):
    """Slip from the pooled pin motion of a TacTip (any pin count; see the module doc).

    Parameters
    ----------
    score : {"reversal", "coherent"}
        The per-frame score (mm/frame).
    lookback : int
        Frames of the reference stretch (``"reversal"`` only).
    gap : int
        Frames between the end of the reference and the current frame
        (``"reversal"`` only; >= 1).
    consecutive : int
        Frames whose raw scores must all reach the threshold (min-combined).
    calibration : {"onset", "sample"}
        How ``fit`` chooses a free threshold. ``"onset"``: on the ROC of per-trial
        units -- each recording's largest score in its first ``onset_frames``
        slip-labelled frames (positive: "detected on time") and its largest score
        before the onset (negative: "an alarm before onset") -- at the best
        Youden point, placed in the middle of the gap of unit scores that gives it
        (not at its edge, so a test slip a little weaker than every training slip
        is still caught). ``"sample"``: the base class's per-sample ROC.
    onset_frames : int
        Frames from the first slip-labelled frame that count as on time.
    threshold : float or None
        Slip when ``score >= threshold`` (mm/frame); None chooses it by
        ``calibration``.
    roc_point : {"youden", "closest"}
        ROC point of the per-sample ROC (``calibration="sample"``).

    Attributes
    ----------
    threshold_ : float
        mm/frame.
    n_pins_in_ : int
        Pins per frame seen in ``fit`` (for reports; any count is scored).
    classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "score": [StrOptions({"reversal", "coherent"})],
        "lookback": [Interval(Integral, 1, None, closed="left")],
        "gap": [Interval(Integral, 1, None, closed="left")],
        "consecutive": [Interval(Integral, 1, None, closed="left")],
        "calibration": [StrOptions({"onset", "sample"})],
        "onset_frames": [Interval(Integral, 1, None, closed="left")],
    }
    n_channels: ClassVar[int | None] = None  # 2 N: x block, y block
    #: any pin count is scored (``slipkit evaluate`` lets another pin layout through)
    pin_count_independent: ClassVar[bool] = True

    def __init__(
        self,
        *,
        score: str = "reversal",
        lookback: int = 20,
        gap: int = 2,
        consecutive: int = 2,
        calibration: str = "onset",
        onset_frames: int = 3,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.score = score
        self.lookback = lookback
        self.gap = gap
        self.consecutive = consecutive
        self.calibration = calibration
        self.onset_frames = onset_frames

    @property
    def span(self) -> int:
        """Frames before the current one that a raw score reads."""
        return int(self.gap) + int(self.lookback) if self.score == "reversal" else 1

    @property
    def window(self) -> int:
        """Frames one decision reads (the current one included)."""
        return self.span + int(self.consecutive)

    def _check_X(self, X: ArrayLike, *, reset: bool) -> FloatArray:
        # Pin-count independent: any even width is scored, so no n_features_in_
        # check after fit (validate_data would refuse 662 channels after 254).
        Xv = np.asarray(
            check_array(X, dtype=np.float64, ensure_all_finite=False), np.float64
        )
        if Xv.shape[1] % 2:
            raise ValueError(
                "PinMotionDetector reads pin frames x0..x{N-1}, y0..y{N-1} (an even "
                f"number of channels); X has {Xv.shape[1]}"
            )
        if reset:
            self.n_features_in_ = Xv.shape[1]
            self.n_pins_in_ = Xv.shape[1] // 2
        return Xv

    def raw_scores(self, X: FloatArray) -> FloatArray:
        """Per-frame score before the ``consecutive`` minimum (one recording)."""
        n_pins = X.shape[1] // 2
        x, y = X[:, :n_pins], X[:, n_pins:]
        out = np.full(len(X), -np.inf)
        s = self.span
        if len(X) <= s:
            return out
        t = np.arange(s, len(X))
        vx, vy, count = mean_displacement(x[t - 1], y[t - 1], x[t], y[t])
        if self.score == "coherent":
            r = np.hypot(vx, vy)
        else:
            g, lb = int(self.gap), int(self.lookback)
            ux, uy, _ = mean_displacement(
                x[t - g - lb], y[t - g - lb], x[t - g], y[t - g]
            )
            r = -(vx * ux + vy * uy) / np.maximum(np.hypot(ux, uy), MIN_REFERENCE_MM)
        out[s:] = np.where(count > 0, r, -np.inf)
        return out

    def _scores(self, X: FloatArray) -> FloatArray:
        r = self.raw_scores(X)
        c = int(self.consecutive)
        if c == 1:
            return r
        out = np.full(len(r), -np.inf)
        if len(r) >= c:
            out[c - 1 :] = np.lib.stride_tricks.sliding_window_view(r, c).min(axis=1)
        return out

    @property
    def window_samples(self) -> int:
        """Frames one score reads (:class:`~slipkit.baselines.generic.RingStream`)."""
        return self.window

    def _new_stream(self) -> RingStream:
        # frame by frame: a ring of the last ``window`` frames, scored by the batch code
        return RingStream(self)


__all__ = [
    "MIN_REFERENCE_MM",
    "PinMotionDetector",
    "mean_displacement",
]
