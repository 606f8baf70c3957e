"""ONNX graphs of the SlipTack onset detectors (:mod:`slipkit.families.sliptack.onset`).

Both detectors' scores are one linear filter of the window plus a constant
(:meth:`~slipkit.families.sliptack.onset.SlipTackOnset.weights`,
:meth:`~slipkit.families.sliptack.onset.SlipTackOnset.bias`): the analytic one's the
signed least-squares slope (mm/s), the learned one's the logit with its scaler and
coefficients folded in. The graph reads the raw float32 window ``(batch, W, 1)``
(oldest first), casts it to float64 (the batch detector's precision), and computes
``x @ w + b`` in one ``MatMul`` (and an ``Add`` for the learned bias); ``NO_SCORE`` (the lowest float32, as
every detector graph) where the result is not finite (a NaN or infinite sample: the
batch detector's ``-inf``). Eight or nine nodes, called on every frame (``hop`` 1).
"""

from __future__ import annotations

import numpy as np
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import GraphBuilder
from slipkit.export.detectors import (
    NO_SCORE,
    DetectorGraph,
    _finish,
    _graph,
    _not_finite,
    _prologue,
)
from slipkit.export.registry import DEFAULT_OPSET, register_exporter
from slipkit.families.sliptack.onset import SlipTackOnset, SlipTackOnsetLogistic


def export_sliptack_onset(
    detector: SlipTackOnset, *, opset: int = DEFAULT_OPSET
) -> DetectorGraph:
    """Export a fitted :class:`SlipTackOnset` or :class:`SlipTackOnsetLogistic` (module docstring).

    Returns
    -------
    DetectorGraph
        Input ``(batch, W, 1)`` float32 raw nib samples, ``score`` ``(batch,)``
        float32: the detector's score at the window's last sample; ``hop`` 1,
        ``first_decision`` ``W - 1``.
    """
    check_is_fitted(detector, "threshold_")
    learned = isinstance(detector, SlipTackOnsetLogistic)
    w = detector.window_samples
    g = GraphBuilder("sliptack_onset_logistic" if learned else "sliptack_onset", opset)
    inp, x = _prologue(g, w, 1)
    flat = g.op("Reshape", x, g.const([-1, w], np.int64), stem="flat")
    lin = g.op("MatMul", flat, g.const(detector.weights(), np.float64), stem="filter")
    bias = detector.bias()
    score = g.op("Add", lin, g.const(bias, np.float64), stem="score64") if bias else lin
    gated = g.op("Where", _not_finite(g, score), g.const(NO_SCORE, np.float64), score)
    if learned:
        what = "the logit of the window's slopes and bend (SlipTackOnsetLogistic)"
        unit = "logit"
    else:
        what = (
            "the nib's deflection rate over the window, slip direction (SlipTackOnset)"
        )
        unit = "signal units per second (mm/s for the nib)"
    model = _finish(g, inp, gated, f"SlipTack onset over {w} frames: {what}")
    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=1,
        hop=1,
        first_decision=w - 1,
        score_meaning=(
            f"{type(detector).__name__}.decision_function at the window's last frame: "
            f"{what}, {unit}; slip ('1') where score >= threshold"
        ),
        input_meaning=(
            f"the last {w} nib samples at {float(detector.rate_hz):g} Hz, oldest first"
        ),
        features={
            "rate_hz": float(detector.rate_hz),
            "window": w,
            "sign": float(detector.sign_),
        },
    )


register_exporter(SlipTackOnset, export_sliptack_onset)

__all__ = ["export_sliptack_onset"]
