"""Exporters of the generic detectors (:mod:`slipkit.baselines.generic`) as window graphs.

Both return a :class:`~slipkit.export.detectors.DetectorGraph`: input ``(batch, W,
n_channels)`` float32 raw samples, oldest first; output ``score`` ``(batch,)``, the
detector's ``decision_function`` at the window's last sample; the lowest float32
(:data:`~slipkit.export.detectors.NO_SCORE`) where the detector scores ``-inf``;
hop 1. They deploy through the stream-detection deployer like every analytic
detector (``slipkit export run=...``).

* :class:`~slipkit.baselines.generic.ChannelChangeDetector`: the differences as one
  constant ``MatMul`` over the window (in float64), ``Abs`` or the learned signs,
  the RMS for ``energy``, the per-channel scales, ``ReduceMax`` / ``ReduceSum``;
  ``NO_SCORE`` where a difference the score reads is not finite (as the batch form).
* :class:`~slipkit.models.window_detector.WindowClassifierDetector`: the fitted Pipeline
  converted by skl2onnx (:func:`slipkit.export.sklearn.export_sklearn`, with
  slipkit's converter for the window statistics), a ``Reshape`` in front (the window
  flattened time-major, as the detector's windows) and the slip probability column
  behind, clipped as the detector clips it; ``NO_SCORE`` for a window holding a non-finite sample.
"""

from __future__ import annotations

import numpy as np
from onnx import helper
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.generic import ChannelChangeDetector
from slipkit.export import window_stats as _window_stats  # noqa: F401  (converter)
from slipkit.export._graph import FLOAT, GraphBuilder
from slipkit.export.detectors import (
    NO_SCORE,
    WINDOW_INPUT,
    DetectorGraph,
    _finish,
    _graph,
    _prologue,
)
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportError,
    finalize_model,
    register_exporter,
)
from slipkit.export.sklearn import export_sklearn
from slipkit.models.window_detector import PROB_CLIP, WindowClassifierDetector


def _not_finite(g: GraphBuilder, v: str) -> str:
    # v - v is NaN exactly for NaN and +-inf.
    return g.op("IsNaN", g.op("Sub", v, v))


def export_channel_change(
    detector: ChannelChangeDetector, *, opset: int = DEFAULT_OPSET
) -> DetectorGraph:
    """Export a fitted :class:`ChannelChangeDetector` over ``window_samples`` samples."""
    check_is_fitted(detector, "threshold_")
    w, s = detector.window_samples, int(detector.span)
    c = int(detector.n_features_in_)
    ends = np.arange(s, w)  # samples of the window whose difference the score reads
    g = GraphBuilder("channel_change", opset)
    inp, x = _prologue(g, w, c)
    # Gather, not a MatMul with a difference matrix: 0 x NaN would let a sample the
    # score does not read (a NaN between the two ends) poison it.
    hi = g.op("Gather", x, g.const(ends, np.int64), axis=1)
    lo = g.op("Gather", x, g.const(ends - s, np.int64), axis=1)
    d = g.op(
        "Div", g.op("Sub", hi, lo), g.const(float(s), np.float64), stem="deriv"
    )  # (batch, m, C), as the batch (x[t] - x[t - s]) / s
    bad = _not_finite(
        g, g.op("ReduceSum", d, g.const([1, 2], np.int64), keepdims=0)
    )  # (batch,)
    if detector.feature == "derivative":
        f = g.op("Reshape", d, g.const([-1, c], np.int64))
        if detector.polarity == "abs":
            f = g.op("Abs", f)
        else:
            f = g.op("Mul", f, g.const(detector.sign_, np.float64))
    else:
        ms = g.op(
            "ReduceSum", g.op("Mul", d, d), g.const([1], np.int64), keepdims=0
        )  # (batch, C)
        f = g.op("Sqrt", g.op("Div", ms, g.const(float(len(ends)), np.float64)))
    z = g.op("Div", f, g.const(detector.scale_, np.float64))
    if detector.combine == "sum":
        score = g.op("ReduceSum", z, g.const([1], np.int64), keepdims=0)
    elif opset >= 18:
        score = g.op("ReduceMax", z, g.const([1], np.int64), keepdims=0)
    else:
        score = g.op("ReduceMax", z, axes=[1], keepdims=0)
    score64 = g.op("Where", bad, g.const(NO_SCORE, np.float64), score)
    model = _finish(
        g,
        inp,
        score64,
        f"ChannelChangeDetector ({detector.feature}, {detector.combine})",
    )
    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=c,
        hop=1,
        first_decision=w - 1,
        score_meaning=(
            f"ChannelChangeDetector.decision_function: per-channel {detector.feature} "
            f"in non-slip spreads, {detector.combine} over channels; slip ('1') where "
            "score >= threshold"
        ),
        input_meaning=f"the last {w} samples of {c} channel(s), oldest first",
        features={
            "feature": detector.feature,
            "span": s,
            "combine": detector.combine,
            "channels": c,
        },
    )


def export_window_classifier(
    detector: WindowClassifierDetector, *, opset: int = DEFAULT_OPSET
) -> DetectorGraph:
    """Export a fitted :class:`WindowClassifierDetector`: skl2onnx pipeline in a window graph."""
    check_is_fitted(detector, "threshold_")
    w, c = int(detector.window), int(detector.n_features_in_)
    inner = export_sklearn(detector.pipeline_, n_features=w * c, opset=opset)
    if inner.score_method != "predict_proba":
        raise ExportError("the window classifier's pipeline must give predict_proba")
    model = inner.model
    graph = model.graph
    x_name = inner.input_name
    del graph.input[:]
    graph.input.append(
        helper.make_tensor_value_info(WINDOW_INPUT, FLOAT, ["batch", w, c])
    )
    shape = f"{x_name}_shape"
    graph.initializer.append(
        helper.make_tensor(shape, helper.TensorProto.INT64, [2], [-1, w * c])
    )
    graph.node.insert(0, helper.make_node("Reshape", [WINDOW_INPUT, shape], [x_name]))
    # column 1 = classes_[1] = slip; NO_SCORE where the window is not finite
    names = {
        "col": "slip_col",
        "one": "slip_col_index",
        "flat": "slip_prob",
        "sum": "window_sum",
        "bad": "window_bad",
        "no": "no_score",
        "neg": "flat_shape",
    }
    graph.initializer.extend(
        [
            helper.make_tensor(names["one"], helper.TensorProto.INT64, [], [1]),
            helper.make_tensor(names["no"], helper.TensorProto.FLOAT, [], [NO_SCORE]),
            helper.make_tensor(names["neg"], helper.TensorProto.INT64, [1], [-1]),
            helper.make_tensor("clip_lo", helper.TensorProto.FLOAT, [], [PROB_CLIP]),
            helper.make_tensor(
                "clip_hi", helper.TensorProto.FLOAT, [], [1.0 - PROB_CLIP]
            ),
            helper.make_tensor("window_axes", helper.TensorProto.INT64, [2], [1, 2]),
        ]
    )
    graph.node.extend(
        [
            helper.make_node(
                "Gather", [inner.score_output, names["one"]], [names["col"]], axis=1
            ),
            helper.make_node("Reshape", [names["col"], names["neg"]], ["slip_raw"]),
            helper.make_node(
                "Clip", ["slip_raw", "clip_lo", "clip_hi"], [names["flat"]]
            ),
            helper.make_node(
                "ReduceSum", [WINDOW_INPUT, "window_axes"], [names["sum"]], keepdims=0
            ),
            helper.make_node("Sub", [names["sum"], names["sum"]], ["window_sum_diff"]),
            helper.make_node("IsNaN", ["window_sum_diff"], [names["bad"]]),
            helper.make_node(
                "Where", [names["bad"], names["no"], names["flat"]], ["score"]
            ),
        ]
    )
    del graph.output[:]
    graph.output.append(helper.make_tensor_value_info("score", FLOAT, ["batch"]))
    model = finalize_model(model)
    return _graph(
        detector,
        model,
        opset=inner.opset,
        window=w,
        channels=c,
        hop=1,
        first_decision=w - 1,
        score_meaning=(
            "WindowClassifierDetector.decision_function: the slip probability of the "
            f"window's pipeline; slip ('1') where score >= threshold "
            f"({float(detector.threshold_):.4g})"
        ),
        input_meaning=f"the last {w} samples of {c} channel(s), oldest first",
        features={"window": w, "channels": c, "model": detector.model},
        **{
            k: v
            for k, v in inner.producers.items()
            if k not in ("slipkit", "onnx", "numpy")
        },
    )


register_exporter(ChannelChangeDetector, export_channel_change)
register_exporter(WindowClassifierDetector, export_window_classifier)

__all__ = ["export_channel_change", "export_window_classifier"]
