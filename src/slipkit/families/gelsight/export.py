"""Exporters of the GelSight stream detectors: ONNX ops only.

:class:`~slipkit.families.gelsight.stream.PinContactDetector` (:func:`export_pin_contact`)
reads one frame per call; the runtime step ``contact_window``
(:mod:`slipkit.runtime.ops.gelsight`) holds its frame counter, pitch and reference.

:class:`~slipkit.families.gelsight.stream.PinDivergenceDetector`:

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

from dataclasses import replace
from typing import Any

import numpy as np
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, GraphBuilder
from slipkit.export.detector_graph import DetectorGraph, _finish, _graph, _prologue
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportError,
    RuntimeSteps,
    StreamContext,
    register_exporter,
    register_runtime_steps,
)
from slipkit.families.gelsight.stream import (
    MIN_PATH,
    PinContactDetector,
    PinDivergenceDetector,
)

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


def contact_window_step(detector: PinContactDetector) -> dict[str, Any]:
    """The runtime step holding the contact window (:mod:`slipkit.runtime.ops.gelsight`)."""
    step: dict[str, Any] = {
        "op": "contact_window",
        "arm": int(detector.arm),
        "window": int(detector.window),
        "min_frames": int(detector.min_frames),
    }
    if detector.horizon is not None:
        step["horizon"] = int(detector.horizon)
    if int(detector.fingertips) > 1:
        step["fingertips"] = int(detector.fingertips)
    return step


def export_pin_contact(
    detector: PinContactDetector, *, opset: int = DEFAULT_OPSET
) -> DetectorGraph:
    """Export a fitted :class:`PinContactDetector`: one frame in, the runtime step
    ``contact_window`` (frame counter, pitch, held reference) before the graph.

    Graph input ``(batch, W + 1, F * 2K)``: the step's window in pitches and its
    decide row, F fingertips side by side. Each fingertip becomes a row of the batch;
    the graph fits the affine map from the window's first to its last frame (``M = c
    c^T``, ``G = c d^T``, ``trace(M^-1 G)`` through the constant adjugate, as
    :func:`export_pin_divergence`), sums the norms of the frame-to-frame mean pin
    steps (the path) and scores ``quantity``; a row that does not decide, or a
    degenerate ``M``, scores ``NO_SCORE``; the largest fingertip score is the score.
    """
    check_is_fitted(detector, "threshold_")
    total, tips = int(detector.n_features_in_), int(detector.fingertips)
    ch = total // tips
    if ch < 6 or ch % 2 or total % tips:
        raise ExportError(
            f"PinContactDetector reads {tips} x 2K pin channels (K >= 3); fit saw "
            f"{total}"
        )
    k, w = ch // 2, int(detector.window)
    g = GraphBuilder("gelsight_pin_contact", opset)
    inp, x = _prologue(g, w + 1, total)
    i64 = np.int64
    if tips > 1:  # (B, W+1, F*2K) -> (B*F, W+1, 2K): one fingertip per batch row
        x = g.op(
            "Reshape",
            g.op(
                "Transpose",
                g.op("Reshape", x, g.const([-1, w + 1, tips, ch], i64)),
                perm=[0, 2, 1, 3],
            ),
            g.const([-1, w + 1, ch], i64),
        )

    def rows(a: int, b: int) -> str:
        return g.op("Slice", x, g.const([a], i64), g.const([b], i64), g.const([1], i64))

    decide = g.op(
        "Greater",
        g.op("Reshape", rows(w, w + 1), g.const([-1, ch], i64)),
        g.const(0.5, np.float64),
    )
    decide = g.op(
        "Reshape",
        g.op("Slice", decide, g.const([0], i64), g.const([1], i64), g.const([1], i64)),
        g.const([-1], i64),
    )  # (B,)
    shape = g.const([-1, 2, k], i64)
    first = g.op("Reshape", g.op("Gather", x, g.const(0, i64), axis=1), shape)
    last = g.op("Reshape", g.op("Gather", x, g.const(w - 1, i64), axis=1), shape)
    c = g.op(
        "Sub", first, g.op("Div", _sum(g, first, [2]), g.const(float(k), np.float64))
    )
    d = g.op("Sub", last, first)
    mm = g.op("MatMul", c, g.op("Transpose", c, perm=[0, 2, 1]))  # (B, 2, 2)
    gg = g.op("MatMul", c, g.op("Transpose", d, perm=[0, 2, 1]))
    flat = g.const([-1, 4], i64)
    mf, gf = g.op("Reshape", mm, flat), g.op("Reshape", gg, flat)
    adj = g.op("MatMul", mf, g.const(_ADJ, np.float64))
    num = _sum(g, g.op("Mul", adj, gf), [1], 0)
    det2 = _sum(g, g.op("Mul", adj, mf), [1], 0)  # 2 det M
    div = g.op("Div", g.op("Mul", num, g.const(2.0, np.float64)), det2)
    # path: sum over the window of |mean pin step| (pitches)
    steps = g.op("Sub", rows(1, w), rows(0, w - 1))  # (B, W-1, 2K)
    steps = g.op("Reshape", steps, g.const([-1, w - 1, 2, k], i64))
    mean_step = g.op(
        "Div", _sum(g, steps, [3], 0), g.const(float(k), np.float64)
    )  # (B, W-1, 2)
    speed = g.op("Sqrt", _sum(g, g.op("Mul", mean_step, mean_step), [2], 0))
    path = _sum(g, speed, [1], 0)  # (B,)
    if detector.quantity == "divergence":
        score = g.op("Abs", div)
    elif detector.quantity == "contraction":
        score = g.op("Neg", div)
    else:
        score = g.op(
            "Div", g.op("Abs", div), g.op("Max", path, g.const(MIN_PATH, np.float64))
        )
    good = g.op("And", decide, g.op("Greater", det2, g.const(0.0, np.float64)))
    score = g.op("Where", good, score, g.const(-np.inf, np.float64))
    if (
        tips > 1
    ):  # the largest fingertip score (ReduceMax takes axes as an input from opset 18)
        per = g.op("Reshape", score, g.const([-1, tips], i64))
        score = (
            g.op("ReduceMax", per, axes=[1], keepdims=0)
            if g.opset < 18
            else g.op("ReduceMax", per, g.const([1], i64), keepdims=0)
        )
    model = _finish(g, inp, score, f"PinContactDetector over {w} pin frames")
    graph = _graph(
        detector,
        model,
        opset=g.opset,
        window=1,
        channels=total,
        hop=1,
        first_decision=int(detector.arm) + int(detector.min_frames) - 1,
        score_meaning=(
            f"{detector.quantity} of the pin field over the contact window "
            "(dimensionless; path in marker pitches); slip where score >= threshold"
        ),
        input_meaning=(
            f"one frame of x_0..x_{k - 1}, y_0..y_{k - 1} (px)"
            + (f" of each of {tips} fingertips in turn" if tips > 1 else "")
            + f"; the runtime step contact_window makes the {w}-frame window in "
            "pitches and its decide row"
        ),
        features={
            "n_pins": k,
            "window": w,
            "arm": int(detector.arm),
            "horizon": detector.horizon,
            "quantity": detector.quantity,
            **({"fingertips": tips} if tips > 1 else {}),
        },
    )
    return replace(
        graph,
        input_shape=("batch", w + 1, total),
        preprocessing=(contact_window_step(detector),),
    )


def contact_runtime_steps(
    detector: PinContactDetector, ctx: StreamContext
) -> RuntimeSteps:
    """The ``contact_window`` step on the gripper PC (counter, pitch, held reference)."""
    del ctx
    step = contact_window_step(detector)
    watch = (
        "the whole recording"
        if detector.horizon is None
        else f"{detector.horizon} frames after arming"
    )
    return RuntimeSteps(
        steps=[step],
        notes=[
            f"contact_window: armed {detector.arm} frames into each stream, watching "
            f"{watch}; start the loop (or reset it) when the grasp closes"
        ],
    )


register_exporter(PinDivergenceDetector, export_pin_divergence)
register_exporter(PinContactDetector, export_pin_contact)
register_runtime_steps(PinContactDetector, contact_runtime_steps)

__all__ = ["contact_window_step", "export_pin_contact", "export_pin_divergence"]
