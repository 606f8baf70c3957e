"""The GelSight marker-field divergence detector, as a slipkit stream detector.

:class:`PinDivergenceDetector` reads one fingertip's pin positions per frame (``x_0 ..
x_{K-1}, y_0 .. y_{K-1}``, px: the importer's stream) and scores each frame by the
magnitude of the divergence of the pin displacement field over the last ``window``
frames: the trace of the least-squares affine map from the window's first positions
to its displacement (:func:`window_divergence`; dimensionless, so the image scale of a
sensor does not matter). It plugs into :class:`~slipkit.train.tasks.detection.StreamDetection`
(``slipkit train experiment=gelsight_divergence``), which chooses the threshold on
validation trials, and exports as an ONNX graph (:mod:`slipkit.families.gelsight.export`).
"""

from __future__ import annotations

from collections import deque
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from sklearn.utils._param_validation import Interval, StrOptions

from slipkit.baselines.base import StreamDetector
from slipkit.families.gelsight.features import FEATURES, FeatureStream, trial_features

FloatArray = NDArray[np.float64]


def window_divergence(first: FloatArray, last: FloatArray) -> float:
    """Divergence of the affine fit to ``last - first`` over the pins (rows ``2K``, px).

    Closed form of the least-squares fit ``d = A (p - mean p) + b``: with ``c`` the
    centred first positions, ``M = c^T c`` and ``G = c^T d``, ``A^T = M^-1 G`` and the
    divergence ``trace(A) = (Syy G00 - Sxy (G01 + G10) + Sxx G11) / det M`` (the same
    sum the ONNX graph computes). Pins NaN in either frame are left out; fewer than
    three pins, or collinear ones, give ``-inf`` (cannot decide).
    """
    k = len(first) // 2
    p0 = np.stack([first[:k], first[k:]], axis=1)
    p1 = np.stack([last[:k], last[k:]], axis=1)
    ok = np.isfinite(p0).all(axis=1) & np.isfinite(p1).all(axis=1)
    if ok.sum() < 3:
        return -np.inf
    c = p0[ok] - p0[ok].mean(axis=0)
    d = p1[ok] - p0[ok]
    m = c.T @ c
    g = c.T @ d
    det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    if det <= 1e-9 * max(m[0, 0] * m[1, 1], 1e-300):
        return -np.inf
    num = m[1, 1] * g[0, 0] - m[0, 1] * (g[0, 1] + g[1, 0]) + m[0, 0] * g[1, 1]
    return float(num / det)


class _DivergenceStream:
    def __init__(self, window: int, threshold: float) -> None:
        self.window, self.threshold = window, threshold
        self.reset()

    def reset(self) -> None:
        self._buf: deque[FloatArray] = deque(maxlen=self.window)

    def update(self, sample: Any) -> tuple[float, bool]:
        self._buf.append(np.asarray(sample, dtype=np.float64).reshape(-1))
        if len(self._buf) < self.window:
            return -np.inf, False
        s = abs(window_divergence(self._buf[0], self._buf[-1]))
        s = s if np.isfinite(s) else -np.inf
        return s, bool(s >= self.threshold)


class PinDivergenceDetector(StreamDetector):
    """Slip where |divergence| of the pin field over the last ``window`` frames reaches
    the threshold.

    Parameters
    ----------
    window : int
        Frames of the window, 2 .. 50 (2 s at 25 fps).
    threshold : float or None
        |divergence| (dimensionless); None: chosen on the training side (the task's
        operating point on validation trials, or the ROC when the labels hold onsets).
    roc_point : {"youden", "closest"}
        The ROC point when the threshold is chosen on per-frame labels.
    quantile : float
        Without per-frame slip labels (trials labelled only ``slipped``) and without a
        threshold, ``threshold_`` is this quantile of the training scores: a start the
        task's operating point replaces.
    """

    n_channels: ClassVar[int | None] = None
    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "window": [Interval(Integral, 2, 50, closed="both")],
        "quantile": [Interval(Real, 0.0, 1.0, closed="both")],
    }

    def __init__(
        self,
        *,
        window: int = 25,
        threshold: float | None = None,
        roc_point: str = "youden",
        quantile: float = 0.99,
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.window = window
        self.quantile = quantile

    def _check_X(self, X: Any, *, reset: bool) -> FloatArray:
        Xv = super()._check_X(X, reset=reset)
        if Xv.shape[1] % 2 or Xv.shape[1] < 6:
            raise ValueError(
                f"{type(self).__name__} reads pin frames x_0..x_{{K-1}}, y_0..y_{{K-1}} (an "
                f"even number of channels, K >= 3 pins); X has {Xv.shape[1]}"
            )
        return Xv

    def _scores(self, X: FloatArray) -> FloatArray:
        w = int(self.window)
        out = np.full(len(X), -np.inf)
        for t in range(w - 1, len(X)):
            s = abs(window_divergence(X[t - w + 1], X[t]))
            out[t] = s if np.isfinite(s) else -np.inf
        return out

    def _calibrate(
        self, X: FloatArray, y: NDArray[np.int_], scores: FloatArray, segments: Any
    ) -> None:
        if self.threshold is None and not np.isfinite(scores).any():
            raise ValueError(
                f"no recording reaches the window of {int(self.window)} frames: no score "
                "to choose a threshold on"
            )
        if self.threshold is None and len(np.unique(y)) < 2:
            finite = scores[np.isfinite(scores)]
            q = float(np.quantile(finite, self.quantile)) if len(finite) else 0.0
            self.threshold_ = q
            empty = np.empty(0)
            self.roc_fpr_, self.roc_tpr_, self.roc_thresholds_ = empty, empty, empty
            self.auc_ = float("nan")
            pred = np.where(np.isfinite(scores), scores, -np.inf) >= q
            self.tpr_ = self.fnr_ = float("nan")
            self.fpr_ = float(pred.mean()) if len(pred) else float("nan")
            self.tnr_ = 1.0 - self.fpr_
            return
        super()._calibrate(X, y, scores, segments)

    def _new_stream(self) -> _DivergenceStream:
        return _DivergenceStream(int(self.window), float(self.threshold_))


#: path floor (marker pitches) of ``divergence_per_path`` (as
#: :data:`slipkit.families.gelsight.detectors.MIN_PATH`; tracking jitter is ~0.01 pitch)
MIN_PATH = 0.02
_DIV, _PATH = FEATURES.index("divergence"), FEATURES.index("path")


def contact_score(quantity: str, features: FloatArray) -> FloatArray:
    """The score of window features ``(n, F)``: ``divergence_per_path``
    (|divergence| / max(path, :data:`MIN_PATH`)), ``divergence`` (|divergence|) or
    ``contraction`` (minus the divergence)."""
    div = features[..., _DIV]
    if quantity == "divergence":
        return np.abs(div)
    if quantity == "contraction":
        return -div
    return np.abs(div) / np.maximum(features[..., _PATH], MIN_PATH)


class _ContactStream:
    def __init__(
        self,
        quantity: str,
        window: int,
        arm: int,
        horizon: int | None,
        min_frames: int,
        threshold: float,
        fingertips: int = 1,
    ) -> None:
        self.quantity, self.threshold = quantity, threshold
        self.arm, self.horizon = arm, horizon
        self._features = [
            FeatureStream(window=window, arm=arm, min_frames=min_frames)
            for _ in range(fingertips)
        ]
        self.reset()

    def reset(self) -> None:
        for f in self._features:
            f.reset()
        self._t = 0

    def update(self, sample: Any) -> tuple[float, bool]:
        t = self._t
        self._t += 1
        if self.horizon is not None and t >= self.arm + self.horizon:
            return -np.inf, False
        frame = np.asarray(sample, dtype=np.float64).reshape(-1)
        s = -np.inf
        for stream, part in zip(
            self._features, np.split(frame, len(self._features)), strict=True
        ):
            f = stream.update(part)
            if f is not None:
                v = float(contact_score(self.quantity, f))
                s = max(s, v if np.isfinite(v) else -np.inf)
        return s, bool(s >= self.threshold)


class PinContactDetector(PinDivergenceDetector):
    """The contact-phase pin-field detector (the report's ``contact_motion``): armed
    ``arm`` frames into the recording, positions in pitches of the first armed frame,
    the window from the first armed frame (held) until it holds ``window`` frames,
    then the last ``window``; it scores ``quantity`` of the affine fit and the field's
    path (:mod:`slipkit.families.gelsight.features`) and stops watching ``horizon``
    frames after arming. With ``fingertips`` > 1 a frame holds each fingertip's pins
    in turn; each is scored on its own and the frame takes the largest score.

    Parameters
    ----------
    quantity : {"divergence_per_path", "divergence", "contraction"}
        The score (:func:`contact_score`).
    window : int
        Frames of the window, 2 .. 50.
    arm : int
        Frames ignored at the start (the contact is made).
    horizon : int or None
        Frames after arming it watches (None: the whole recording).
    min_frames : int
        Armed frames before the first score.
    fingertips : int
        Fingertips side by side in a frame (``2K`` channels each: the importer's
        ``fingertips`` stream holds both).
    threshold, roc_point, quantile
        As :class:`PinDivergenceDetector` (the task's operating point chooses it).
    """

    QUANTITIES = ("divergence_per_path", "divergence", "contraction")

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **PinDivergenceDetector._parameter_constraints,
        "quantity": [StrOptions(set(QUANTITIES))],
        "arm": [Interval(Integral, 0, None, closed="left")],
        "horizon": [Interval(Integral, 1, None, closed="left"), None],
        "min_frames": [Interval(Integral, 2, 50, closed="both")],
        "fingertips": [Interval(Integral, 1, 8, closed="both")],
    }

    def __init__(
        self,
        *,
        quantity: str = "divergence_per_path",
        window: int = 50,
        arm: int = 3,
        horizon: int | None = 200,
        min_frames: int = 5,
        fingertips: int = 1,
        threshold: float | None = None,
        roc_point: str = "youden",
        quantile: float = 0.99,
    ) -> None:
        super().__init__(
            window=window, threshold=threshold, roc_point=roc_point, quantile=quantile
        )
        self.quantity = quantity
        self.arm = arm
        self.horizon = horizon
        self.min_frames = min_frames
        self.fingertips = fingertips

    def _check_X(self, X: Any, *, reset: bool) -> FloatArray:
        Xv = StreamDetector._check_X(self, X, reset=reset)
        n = int(self.fingertips)
        if Xv.shape[1] % (2 * n) or Xv.shape[1] < 6 * n:
            raise ValueError(
                f"{type(self).__name__} reads {n} fingertip(s) of pin frames x_0..x_{{K-1}}, "
                f"y_0..y_{{K-1}} each (2K channels per fingertip, K >= 3 pins); X has "
                f"{Xv.shape[1]}"
            )
        return Xv

    def _scores(self, X: FloatArray) -> FloatArray:
        s = np.full(len(X), -np.inf)
        for part in np.split(X, int(self.fingertips), axis=1):
            f = trial_features(
                part,
                window=int(self.window),
                arm=int(self.arm),
                min_frames=int(self.min_frames),
            )
            with np.errstate(invalid="ignore", divide="ignore"):
                one = contact_score(self.quantity, f)
            s = np.maximum(s, np.where(np.isfinite(one), one, -np.inf))
        if self.horizon is not None:
            s[int(self.arm) + int(self.horizon) :] = -np.inf
        return s

    def _new_stream(self) -> _ContactStream:  # type: ignore[override]
        return _ContactStream(
            self.quantity,
            int(self.window),
            int(self.arm),
            None if self.horizon is None else int(self.horizon),
            int(self.min_frames),
            float(self.threshold_),
            int(self.fingertips),
        )


__all__ = [
    "MIN_PATH",
    "PinContactDetector",
    "PinDivergenceDetector",
    "contact_score",
    "window_divergence",
]
