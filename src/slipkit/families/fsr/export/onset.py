"""ONNX graphs of the FSR onset detectors (:mod:`slipkit.families.fsr.onset`).

Both read the float64 window of the last ``W = lead + edge + 1 + rebound`` samples of the
signed signal ``sign (v - v_rest)`` that the runtime op ``press_sign`` makes on the
gripper PC (one-sample blocks: :func:`~slipkit.families.fsr.onset.slip_sign_step`),
shape ``(batch, W)``, and return a float64 ``score`` ``(batch,)``; the runtime calls
them on every sample (``hop = 1``).

* :class:`~slipkit.families.fsr.onset.FSROnset`: one ``MatMul`` gives every
  difference the rules read (:func:`~slipkit.families.fsr.onset.onset_matrix`: each
  column two entries +-1, so the exact difference, as numpy's), then ``column -
  (coef E + const)`` (``Mul``, ``Add``, ``Sub``), ``ReduceMin >= 0`` and ``Where`` of
  the release ``E``: ten nodes, the batch detector's own float64 operations.
* :class:`~slipkit.families.fsr.onset.FSROnsetLogistic`: the shape numerators as
  the maxima of four groups of exact differences (one ``MatMul``, ``Reshape``,
  ``ReduceMax``), the five features (``Div``, ``Clip``, ``Log``, ``Min``,
  ``Concat``), the logit (``MatMul``, ``Add``) and the candidate gate (``Gemm``,
  ``ReduceMin``, ``GreaterOrEqual``, ``Where``): sixteen nodes, as few as the math
  allows (node dispatch, not arithmetic, is a batch-1 call's cost).

``NO_SCORE`` (the lowest float32, as every detector graph) where the batch detector
scores ``-inf``. A window holding a NaN scores ``NO_SCORE`` or NaN (never a finite
score the batch detector lacks); the runtime loop does not call the graph on one.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import onnx
from onnx import helper
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, GraphBuilder
from slipkit.export.detectors import (
    NO_SCORE,
    SCORE,
    WINDOW_INPUT,
    DetectorGraph,
    _axes,
    _graph,
)
from slipkit.export.registry import (
    DEFAULT_OPSET,
    RuntimeSteps,
    StreamContext,
    register_exporter,
    register_runtime_steps,
)
from slipkit.families.fsr.export.touch_slip import _float32_range
from slipkit.families.fsr.onset import (
    FEATURE_CLIP,
    FSROnset,
    FSROnsetLogistic,
    slip_sign_step,
)


def _cols(g: GraphBuilder, t: str, start: int, stop: int) -> str:
    i64 = np.int64
    return g.op("Slice", t, g.const([start], i64), g.const([stop], i64), _axes(g, 1))


def _reduce_min(g: GraphBuilder, t: str, keepdims: int, stem: str) -> str:
    if g.opset >= 18:
        return g.op("ReduceMin", t, _axes(g, 1), keepdims=keepdims, stem=stem)
    return g.op("ReduceMin", t, axes=[1], keepdims=keepdims, stem=stem)


def export_fsr_onset(
    detector: FSROnset, *, opset: int = DEFAULT_OPSET
) -> DetectorGraph:
    """Export a fitted :class:`FSROnset` or :class:`FSROnsetLogistic` (module docstring).

    Returns
    -------
    DetectorGraph
        Input ``(batch, W)`` float64 (after ``press_sign``), ``score`` ``(batch,)``
        float64: the detector's score at the window's last sample; ``hop`` 1,
        ``first_decision`` the detector's first decided sample of a recording
        (``max(W - 1, rest_samples - 1)``), ``preprocessing`` the ``press_sign`` step.
    """
    check_is_fitted(detector, "threshold_")
    learned = isinstance(detector, FSROnsetLogistic)
    g = GraphBuilder("fsr_onset_logistic" if learned else "fsr_onset", opset)
    w = detector.window_samples
    inp = helper.make_tensor_value_info(WINDOW_INPUT, DOUBLE, ["batch", w])
    if learned:
        assert isinstance(detector, FSROnsetLogistic)
        check_is_fitted(detector, "coef_")
        # a logit never leaves the float32 range: no clip, the Where writes the score
        _logistic(g, detector)
        what = "the logit of the onset window's shape (FSROnsetLogistic)"
    else:
        cols = g.op(
            "MatMul", WINDOW_INPUT, g.const(detector.matrix(), np.float64), stem="cols"
        )
        release = _cols(g, cols, 0, 1)  # (batch, 1)
        coef, const = detector._conditions()
        bound = g.op(
            "Add",
            g.op("Mul", release, g.const(coef[None, :], np.float64)),
            g.const(const[None, :], np.float64),
            stem="bound",
        )
        low = _reduce_min(g, g.op("Sub", cols, bound, stem="margin"), 0, "worst")
        ok = g.op("GreaterOrEqual", low, g.const(0.0, np.float64), stem="passes")
        flat = g.op("Reshape", release, g.const([-1], np.int64), stem="release")
        score = g.op("Where", ok, flat, g.const(NO_SCORE, np.float64), stem="gated")
        what = "the release E (V) where it rings back (FSROnset)"
        _float32_range(g, score)
    g.nodes[-1].output[0] = SCORE  # the last node writes the score itself
    model = g.build(
        [inp],
        [helper.make_tensor_value_info(SCORE, DOUBLE, ["batch"])],
        doc=f"FSR slip onset over {w} samples: {what}; NO_SCORE unless touched",
    )
    return _onset_graph(detector, model, g.opset, what)


def _logistic(g: GraphBuilder, det: FSROnsetLogistic) -> str:
    """The learned detector's nodes (features, logit, candidate gate)."""
    f64 = np.float64
    q, e, m = det.lead_samples, det.edge_samples, det.rebound_samples
    w = det.window_samples
    k, n = q + e, w - 1
    width = max(m, q, 1)
    # the numerators of FEATURES[:4] as the maxima of four groups of exact differences:
    # the fall back (repeated), the rises after, the rises before (padded by repeats;
    # none: 0), the last step (repeated)
    groups = np.zeros((w, 4, width))
    for j in range(width):
        groups[k, 0, j] += 1.0
        groups[n, 0, j] -= 1.0
        a = k + 1 + min(j, m - 1)
        groups[a, 1, j] += 1.0
        groups[k, 1, j] -= 1.0
        if q:
            i = k - e - q + min(j, q - 1)
            groups[i + 1, 2, j] += 1.0
            groups[i, 2, j] -= 1.0
        groups[k, 3, j] += 1.0
        groups[k - 1, 3, j] -= 1.0
    diffs = g.op(
        "Reshape",
        g.op("MatMul", WINDOW_INPUT, g.const(groups.reshape(w, 4 * width), f64)),
        g.const([-1, 4, width], np.int64),
        stem="groups",
    )
    if g.opset >= 18:
        most = g.op("ReduceMax", diffs, g.const([2], np.int64), keepdims=0)
    else:
        most = g.op("ReduceMax", diffs, axes=[2], keepdims=0)
    # the candidate gate's [E - min_step_V, -s[n] - delta] in one Gemm; E alone in another
    gate = np.zeros((w, 2))
    gate[k, 0], gate[k - e, 0], gate[n, 1] = 1.0, -1.0, -1.0
    pick = np.zeros((w, 1))
    pick[k, 0], pick[k - e, 0] = 1.0, -1.0
    release = g.op("MatMul", WINDOW_INPUT, g.const(pick, f64), stem="release")
    shape = g.op(
        "Clip",
        g.op("Div", most, release, stem="per_release"),
        g.const(-FEATURE_CLIP, f64),
        g.const(FEATURE_CLIP, f64),
        stem="shape",
    )
    size = g.op(
        "Min",
        g.op("Log", g.op("Div", release, g.const(float(det.size_V), f64))),
        g.const(0.0, f64),
        stem="size",
    )
    logit = g.op(
        "Add",
        g.op(
            "MatMul",
            g.op("Concat", shape, size, axis=1, stem="features"),
            g.const(det.coef_, f64),
        ),
        g.const(float(det.intercept_), f64),
        stem="logit",
    )  # (batch,)
    margin = g.op(
        "Gemm",
        WINDOW_INPUT,
        g.const(gate, f64),
        g.const([-float(det.min_step_V), -float(det.delta_)], f64),
        stem="candidate_margin",
    )
    ok = g.op(
        "GreaterOrEqual",
        _reduce_min(g, margin, 0, "candidate_worst"),
        g.const(0.0, f64),
        stem="candidate",
    )
    return g.op("Where", ok, logit, g.const(NO_SCORE, f64), stem="gated")


def _onset_graph(
    detector: FSROnset, model: onnx.ModelProto, opset: int, what: str
) -> DetectorGraph:
    w = detector.window_samples
    step = slip_sign_step(detector)
    sign = (
        "the recording's own rest and press direction (latched at its first sample "
        f"further than {step['delta']:g} V from rest)"
        if "sign" not in step
        else f"the recording's own rest, sign {step['sign']:+d}"
    )
    graph = _graph(
        detector,
        model,
        opset=opset,
        window=w,
        channels=1,
        hop=1,
        first_decision=max(w - 1, int(detector.rest_samples) - 1),
        score_meaning=(
            f"{type(detector).__name__}.decision_function at the window's last sample: "
            f"{what}; {NO_SCORE:g} (the detector's -inf) when untouched or no "
            "candidate; slip ('1') where score >= threshold"
        ),
        input_meaning=(
            f"the last {w} FSR voltage samples (V) at {detector.rate_hz:g} Hz, oldest "
            f"first, after press_sign: sign * (v - v_rest) with {sign}"
        ),
        features={
            "polarity": detector._polarity,
            "rate_hz": float(detector.rate_hz),
            "lead_samples": detector.lead_samples,
            "edge_samples": detector.edge_samples,
            "rebound_samples": detector.rebound_samples,
            "delta": float(detector.delta_),
        },
    )
    return replace(
        graph,
        input_shape=("batch", w),
        input_dtype="float64",
        preprocessing=(step,),
    )


def onset_runtime_steps(det: FSROnset, ctx: StreamContext) -> RuntimeSteps:
    """The onset detectors read the FSR's signed signal per sample: ``press_sign``."""
    del ctx
    return RuntimeSteps(
        steps=[slip_sign_step(det)],
        notes=[
            "press_sign: the stream's rest level (mean of its first "
            f"{det.rest_samples} samples) and its wiring sign, latched on the "
            "gripper PC; start the loop (or reset it) at rest before each grasp"
        ],
    )


register_exporter(FSROnset, export_fsr_onset)
register_runtime_steps(FSROnset, onset_runtime_steps)

__all__ = ["export_fsr_onset"]
