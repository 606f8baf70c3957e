"""Exporter of :class:`~slipkit.families.gelsight.stream.PinDivergenceDetector`: ONNX ops only.

Input: the last ``window`` frames of one fingertip's pin positions ``(batch, W, 2K)``
(px, ``x_0..x_{K-1}`` then ``y_0..y_{K-1}``, oldest first; the marker tracker stays on
the capture side). Output ``score`` ``(batch,)``: |divergence| of the least-squares
affine fit to the displacement from the window's first to its last frame, the closed
form of :func:`~slipkit.families.gelsight.stream.window_divergence`: the centred first
positions ``c`` (pins NaN in either frame weigh 0), ``M = c c^T`` and ``G = c d^T``
as two ``MatMul``, then ``trace(M^-1 G)`` as one ``MatMul`` with a constant 4 x 4
matrix (the adjugate's signs) and two sums. Fewer than three pins or a degenerate
``M`` score :data:`~slipkit.export.detector_graph.NO_SCORE`.
"""

from __future__ import annotations

import numpy as np
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, GraphBuilder
from slipkit.export.detector_graph import DetectorGraph, _finish, _graph, _prologue
from slipkit.export.registry import DEFAULT_OPSET, ExportError, register_exporter
from slipkit.families.gelsight.stream import PinDivergenceDetector

#: flattened [Sxx, Sxy, Sxy, Syy] @ _ADJ = [Syy, -Sxy, -Sxy, Sxx] (the adjugate, row-major)
_ADJ = np.array(
    [[0, 0, 0, 1], [0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0]], dtype=np.float64
)


def _sum(g: GraphBuilder, x: str, axes: list[int], keepdims: int = 1) -> str:
    return g.op("ReduceSum", x, g.const(axes, np.int64), keepdims=keepdims)


def export_pin_divergence(
    detector: PinDivergenceDetector, *, opset: int = DEFAULT_OPSET
) -> DetectorGraph:
    """Export a fitted :class:`PinDivergenceDetector` for the channel count seen in ``fit``."""
    check_is_fitted(detector, "threshold_")
    ch = int(detector.n_features_in_)
    if ch < 6 or ch % 2:
        raise ExportError(
            f"PinDivergenceDetector reads 2K pin channels (K >= 3); fit saw {ch}"
        )
    k, w = ch // 2, int(detector.window)
    g = GraphBuilder("gelsight_pin_divergence", opset)
    inp, x = _prologue(g, w, ch)
    idx0, idx1 = g.const(0, np.int64), g.const(w - 1, np.int64)
    shape = g.const([-1, 2, k], np.int64)
    first = g.op("Reshape", g.op("Gather", x, idx0, axis=1), shape)  # (B, 2, K)
    last = g.op("Reshape", g.op("Gather", x, idx1, axis=1), shape)
    zero = g.const(0.0, np.float64)

    def finite(v: str) -> str:
        return g.op("Not", g.op("IsNaN", g.op("Sub", v, v)))

    ok = g.op("And", finite(first), finite(last))
    m = (
        g.op(
            "ReduceMin",
            g.op("Cast", ok, to=DOUBLE),
            axes=[1],
            keepdims=1,
        )
        if opset < 18
        else g.op(
            "ReduceMin", g.op("Cast", ok, to=DOUBLE), g.const([1], np.int64), keepdims=1
        )
    )  # (B, 1, K): both coordinates finite in both frames
    p0 = g.op("Mul", g.op("Where", ok, first, zero), m)
    p1 = g.op("Mul", g.op("Where", ok, last, zero), m)
    n = _sum(g, m, [2])  # (B, 1, 1)
    mean = g.op("Div", _sum(g, p0, [2]), g.op("Max", n, g.const(1.0, np.float64)))
    c = g.op("Mul", g.op("Sub", p0, mean), m)
    d = g.op("Sub", p1, p0)
    mm = g.op("MatMul", c, g.op("Transpose", c, perm=[0, 2, 1]))  # (B, 2, 2)
    gg = g.op("MatMul", c, g.op("Transpose", d, perm=[0, 2, 1]))
    flat = g.const([-1, 4], np.int64)
    mf, gf = g.op("Reshape", mm, flat), g.op("Reshape", gg, flat)
    adj = g.op("MatMul", mf, g.const(_ADJ, np.float64))
    num = _sum(g, g.op("Mul", adj, gf), [1], 0)
    det2 = _sum(g, g.op("Mul", adj, mf), [1], 0)  # 2 det M
    scale = g.op(
        "Mul", g.op("Reshape", mf, flat), g.const([1.0, 0.0, 0.0, 1.0], np.float64)
    )
    sxx_syy = (
        g.op(
            "ReduceProd",
            g.op("Add", scale, g.const([0.0, 1.0, 1.0, 0.0], np.float64)),
            axes=[1],
            keepdims=0,
        )
        if opset < 18
        else g.op(
            "ReduceProd",
            g.op("Add", scale, g.const([0.0, 1.0, 1.0, 0.0], np.float64)),
            g.const([1], np.int64),
            keepdims=0,
        )
    )
    div = g.op("Abs", g.op("Div", g.op("Mul", num, g.const(2.0, np.float64)), det2))
    good = g.op(
        "And",
        g.op(
            "Greater",
            g.op("Reshape", n, g.const([-1], np.int64)),
            g.const(2.5, np.float64),
        ),
        g.op(
            "Greater",
            g.op("Div", det2, g.const(2.0, np.float64)),
            g.op("Mul", sxx_syy, g.const(1e-9, np.float64)),
        ),
    )
    score = g.op("Where", good, div, g.const(-np.inf, np.float64))
    model = _finish(g, inp, score, f"PinDivergenceDetector over {w} pin frames")
    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=ch,
        hop=1,
        first_decision=w - 1,
        score_meaning=(
            "|divergence| of the affine fit to the pin displacement from the window's "
            "first to its last frame (dimensionless); slip where score >= threshold"
        ),
        input_meaning=(
            f"the last {w} frames of x_0..x_{k - 1}, y_0..y_{k - 1} (px, NaN: pin "
            "missing), oldest first"
        ),
        features={"n_pins": k, "window": w},
    )


register_exporter(PinDivergenceDetector, export_pin_divergence)

__all__ = ["export_pin_divergence"]
