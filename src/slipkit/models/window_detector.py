"""A learned per-sample slip detector for any stream: window statistics -> classifier.

:class:`WindowClassifierDetector` keeps the :class:`~slipkit.baselines.base.StreamDetector`
contract (``fit(X, y, segments)``, ``decision_function``, ``threshold_`` from the ROC,
batch and streaming forms equal), so the stream-detection task
(:class:`~slipkit.train.tasks.detection.StreamDetection`) scores it beside the analytic
:class:`~slipkit.baselines.generic.ChannelChangeDetector` on the same trials, and the
same deployer ships it. Inside: the last ``window`` samples of every channel ->
per-channel window statistics (:class:`~slipkit.models.window_features.WindowStatistics`)
-> standardise -> logistic regression or a small MLP (a scikit-learn Pipeline, exported
by skl2onnx); the score is the slip probability at the window's last sample. Windows
never cross a recording boundary; a window holding a non-finite sample scores ``-inf``
(and is left out of training). Labels are the task's per-sample labels at the window's
end. Scores are clipped to ``[2**-20, 1 - 2**-20]`` (:data:`PROB_CLIP`).
"""

from __future__ import annotations

from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from sklearn.base import clone
from sklearn.linear_model import LogisticRegression
from sklearn.neural_network import MLPClassifier
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils._param_validation import Interval, StrOptions

from slipkit.baselines.base import FloatArray, StreamDetector, segment_bounds
from slipkit.baselines.generic import OnsetCalibration, RingStream
from slipkit.models.window_features import STATS, WindowStatistics

#: Scores are slip probabilities clipped to ``[PROB_CLIP, 1 - PROB_CLIP]``: the ONNX
#: graph computes them in float32, which cannot tell 1 - 1e-9 from 1, so a threshold
#: the ROC puts at 0.999999999 would flip decisions in the graph. 2**-20 makes both
#: bounds exact in float32 (resolution near 1: 6e-8).
PROB_CLIP = 2.0**-20


class WindowClassifierDetector(OnsetCalibration, StreamDetector):
    """A learned per-sample slip classifier on windows of any stream (see the module doc).

    Parameters
    ----------
    window : int
        Samples per window (the current one last).
    stats : sequence of str
        Window statistics per channel (a subset of
        :data:`slipkit.models.window_features.STATS`).
    subtract_first : bool
        Subtract each window's first sample before the statistics.
    model : {"logreg", "mlp"}
        Logistic regression (``C``) or an MLP (``hidden``, ReLU, adam, early stopping).
    C : float
        Inverse L2 strength of the logistic regression.
    hidden : sequence of int
        MLP hidden layer sizes.
    class_weight : "balanced" or None
        Logistic regression class weights (slip samples are usually rare).
    random_state : int
        Seed of the MLP.
    calibration : {"onset", "sample"}
        How a free threshold is chosen
        (:class:`~slipkit.baselines.generic.OnsetCalibration`): per-recording units
        mid-gap, or the per-sample ROC.
    onset_frames : int or None
        Samples from the onset that count as on time (None: the whole slip).
    threshold : float or None
        Slip when the slip probability ``>= threshold``; None: chosen by
        ``calibration``.
    roc_point : {"youden", "closest"}
        ROC point of the per-sample ROC.

    Attributes
    ----------
    pipeline_ : sklearn.pipeline.Pipeline
        ``WindowStatistics -> StandardScaler -> classifier`` on flattened windows
        (time-major, ``window x n_channels``); exported whole by skl2onnx.
    threshold_, classes_, roc_fpr_, roc_tpr_, roc_thresholds_, auc_, tpr_, tnr_, fpr_, fnr_, n_features_in_
        See :class:`~slipkit.baselines.base.StreamDetector`.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "window": [Interval(Integral, 1, None, closed="left")],
        "stats": [list, tuple],
        "subtract_first": ["boolean"],
        "model": [StrOptions({"logreg", "mlp"})],
        "C": [Interval(Real, 0, None, closed="neither")],
        "hidden": [list, tuple],
        "class_weight": [StrOptions({"balanced"}), None],
        "random_state": [Interval(Integral, 0, None, closed="left")],
        "calibration": [StrOptions({"onset", "sample"})],
        "onset_frames": [Interval(Integral, 1, None, closed="left"), None],
    }
    n_channels: ClassVar[int | None] = None

    def __init__(
        self,
        *,
        window: int = 10,
        stats: Sequence[str] = STATS,
        subtract_first: bool = False,
        model: str = "logreg",
        C: float = 1.0,
        hidden: Sequence[int] = (32,),
        class_weight: str | None = "balanced",
        random_state: int = 0,
        calibration: str = "onset",
        onset_frames: int | None = None,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.calibration = calibration
        self.onset_frames = onset_frames
        self.window = window
        self.stats = stats
        self.subtract_first = subtract_first
        self.model = model
        self.C = C
        self.hidden = hidden
        self.class_weight = class_weight
        self.random_state = random_state

    @property
    def window_samples(self) -> int:
        """Samples one score reads."""
        return int(self.window)

    def _pipeline(self, n_channels: int) -> Pipeline:
        clf: Any
        if self.model == "logreg":
            clf = LogisticRegression(
                C=float(self.C), class_weight=self.class_weight, max_iter=2000
            )
        else:
            clf = MLPClassifier(
                hidden_layer_sizes=tuple(int(h) for h in self.hidden),
                early_stopping=True,
                max_iter=500,
                random_state=int(self.random_state),
            )
        return Pipeline(
            [
                (
                    "stats",
                    WindowStatistics(
                        n_channels=n_channels,
                        stats=tuple(self.stats),
                        subtract_first=bool(self.subtract_first),
                    ),
                ),
                ("scale", StandardScaler()),
                ("clf", clone(clf)),
            ]
        )

    def windows(self, X: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
        """Flattened windows of ONE recording and the sample each ends on."""
        w, c = int(self.window), X.shape[1]
        if len(X) < w:
            return np.empty((0, w * c)), np.empty(0, dtype=np.intp)
        view = sliding_window_view(X, (w, c))[:, 0]  # (n - w + 1, w, c)
        return view.reshape(len(view), w * c), np.arange(w - 1, len(X))

    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> WindowClassifierDetector:
        """Fit the pipeline on the finite windows (label at the window's end), then the threshold."""
        self._validate_params()
        Xv = self._check_X(X, reset=True)
        yv = np.asarray(y).astype(int).reshape(-1)
        if yv.shape != (len(Xv),):
            raise ValueError(f"y must have shape ({len(Xv)},); got {yv.shape}")
        parts, labels = [], []
        for a, b in segment_bounds(len(Xv), segments):
            win, ends = self.windows(Xv[a:b])
            ok = np.isfinite(win).all(axis=1)
            parts.append(win[ok])
            labels.append(yv[a:b][ends[ok]])
        W = np.vstack(parts) if parts else np.empty((0, 0))
        wy = np.concatenate(labels) if labels else np.empty(0, int)
        if len(np.unique(wy)) < 2:
            raise ValueError(
                f"training windows of {self.window} samples hold only classes "
                f"{np.unique(wy).tolist()}; need slip and non-slip windows"
            )
        self.pipeline_ = self._pipeline(Xv.shape[1]).fit(W, wy)
        super().fit(Xv, yv, segments=segments)
        return self

    def _scores(self, X: FloatArray) -> FloatArray:
        out = np.full(len(X), -np.inf)
        win, ends = self.windows(X)
        if len(ends) == 0:
            return out
        ok = np.isfinite(win).all(axis=1)
        if ok.any():
            p = self.pipeline_.predict_proba(win[ok])[:, 1]
            out[ends[ok]] = np.clip(p, PROB_CLIP, 1.0 - PROB_CLIP)
        return out

    def _new_stream(self) -> RingStream:
        return RingStream(self)


__all__ = ["PROB_CLIP", "WindowClassifierDetector"]
