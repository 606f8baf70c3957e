"""Template: a stream detector for a new sensor family, its ONNX exporter, its registration.

Copy this file to ``src/slipkit/families/<family>/detector.py``, rename ``ForceDrop``,
replace the score in ``_scores`` and the same arithmetic in ``export_force_drop``, and
name the module in the family record's ``exporters`` (``FAMILY`` in the folder's
``__init__.py``) so ``slipkit export`` registers it. ``tests/test_extension_template.py`` runs this file as it
stands: fit, batch and streaming decisions agree, the graph matches the detector in
onnxruntime. Keep those three checks for your detector (docs/extending.md).

The example: slip when one force channel falls, the mean of a window's older half minus
the mean of its newer half (N) reaching a threshold chosen on the ROC of labelled
recordings (``fit``).
"""

from __future__ import annotations

from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import StreamDetector
from slipkit.baselines.generic import RingStream
from slipkit.export._graph import GraphBuilder
from slipkit.export.detector_graph import DetectorGraph, _finish, _graph, _prologue
from slipkit.export.registry import DEFAULT_OPSET

FloatArray = NDArray[np.float64]


class ForceDrop(StreamDetector):
    """Slip when the force's older half-window mean exceeds its newer half's by ``threshold_``.

    Parameters
    ----------
    window : int
        Samples per decision (even, >= 2); the first ``window - 1`` samples of a
        recording cannot decide (score ``-inf``).
    threshold : float, optional
        Fixed threshold (N); None: chosen on the ROC in ``fit``.
    roc_point : {"youden", "closest"}
        The ROC point ``fit`` keeps.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **StreamDetector._parameter_constraints,
        "window": [Interval(Integral, 2, None, closed="left")],
    }
    n_channels: ClassVar[int | None] = 1  # one force channel

    def __init__(
        self,
        *,
        window: int = 8,
        threshold: float | None = None,
        roc_point: str = "youden",
    ) -> None:
        super().__init__(threshold=threshold, roc_point=roc_point)
        self.window = window

    @property
    def window_samples(self) -> int:
        """Samples one score reads (the streaming ring's length)."""
        return int(self.window)

    def _scores(self, X: FloatArray) -> FloatArray:
        w, half = int(self.window), int(self.window) // 2
        f = X[:, 0]
        out = np.full(len(f), -np.inf)
        if len(f) < w:
            return out
        windows = np.lib.stride_tricks.sliding_window_view(f, w)
        out[w - 1 :] = windows[:, : w - half].mean(axis=1) - windows[
            :, w - half :
        ].mean(axis=1)
        return out

    def _new_stream(self) -> RingStream:
        return RingStream(self)


def export_force_drop(
    detector: ForceDrop, *, opset: int = DEFAULT_OPSET
) -> DetectorGraph:
    """The detector's score as ONNX ops on a ``(batch, window, 1)`` input."""
    check_is_fitted(detector, "threshold_")
    w, half = int(detector.window), int(detector.window) // 2
    g = GraphBuilder("force_drop", opset)
    inp, x = _prologue(g, w, 1)  # float32 in, float64 inside

    def mean(start: int, stop: int) -> str:
        part = g.op(
            "Slice",
            x,
            g.const([start], np.int64),
            g.const([stop], np.int64),
            g.const([1], np.int64),
        )
        summed = g.op("ReduceSum", part, g.const([1, 2], np.int64), keepdims=0)
        return g.op("Div", summed, g.const(float(stop - start), np.float64))

    score = g.op("Sub", mean(0, w - half), mean(w - half, w))
    model = _finish(g, inp, score, f"ForceDrop over {w} samples")
    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=1,
        hop=1,
        first_decision=w - 1,
        score_meaning="older half-window mean minus newer half-window mean (N)",
        input_meaning=f"the last {w} force samples (N), oldest first",
        features={"window": w},
    )


# In the family's module: register the exporter where the class is defined.
#   from slipkit.export.registry import register_exporter
#   register_exporter(ForceDrop, export_force_drop)
