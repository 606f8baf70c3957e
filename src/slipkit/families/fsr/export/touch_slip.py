"""Exporter of the FSR touch-and-slip detector (the two-block graph, the gated and confirmed
variants) and the runtime op ``press_sign`` it needs for voltage input.

The graph contract: :mod:`slipkit.export.detectors`.

The graph of :class:`~slipkit.families.fsr.touch_slip.FSRTouchSlip`: ``W = 2 block`` (10): the two
block means, their backward difference over the cycle time, one sign, the touch
gate (the plain two-block graph is four nodes: ``Gemm``, ``Add``, ``ReduceMin``,
``Clip``; :func:`_fsr_gated`). Decision instants are block ends: ``hop = block``
(5). The batch detector
averages each recording's first 10 samples into its rest level; for voltage input
the runtime op ``press_sign`` does the same per stream (:func:`fsr_press_sign_step`),
with the fitted polarity's sign, or, for ``polarity_ == "per_recording"`` (training
wirings of both signs), the sign latched at the stream's first press, and the graph
reads ``sign * (v - v_rest)`` with rest 0 and the paper's sign: its rest and gate
are the recording's own, so a recording of the other wiring is never touched, as
in the batch detector. Force input, or an explicit ``rest=...``: the
gate is against a **fixed rest voltage**, a calibration constant in the graph.

Importing this module registers the exporter, the runtime steps and the parity check's gate
margin (:func:`fsr_gate_margin`) for :class:`FSRTouchSlip`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import onnx
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray
from onnx import helper
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, GraphBuilder
from slipkit.export.detector_graph import (
    _F32_MAX,
    NO_SCORE,
    SCORE,
    WINDOW_INPUT,
    DetectorGraph,
    _axes,
    _graph,
    _not_finite,
)
from slipkit.export.detector_parity import register_gate_margin
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportError,
    RuntimeSteps,
    StreamContext,
    register_exporter,
    register_runtime_steps,
)
from slipkit.families.fsr.physics import rest_voltage
from slipkit.families.fsr.touch_slip import FSRTouchSlip


# -- FSR --------------------------------------------------------------------------------
def export_fsr_touch_slip(
    detector: FSRTouchSlip,
    *,
    rest: float | None = None,
    gate: bool = True,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`FSRTouchSlip` over a window of two blocks.

    Parameters
    ----------
    detector : FSRTouchSlip
        Fitted (``threshold_`` is alpha, V/s or N/s).
    rest : float or None
        None (voltage input, with the gate): the rest level comes from the stream,
        as in the batch detector, which averages the first ``rest_samples`` of every
        recording: the graph's ``preprocessing`` is the runtime op ``press_sign``
        (:func:`fsr_press_sign_step`) and the graph reads ``sign * (v - v_rest)``.
        A float: the rest voltage ``v_rest`` (V) of the touch gate as a constant of
        the graph (measured at calibration, the mean of unloaded samples), no
        preprocessing; the graph then differs from the batch detector wherever a
        recording's rest mean differs from it (a recording of the other wiring is
        touched all along). Force input, or ``gate=False``, with None: the detector's
        ``rest_V_`` (the median rest voltage of its training recordings), or, if that
        is not finite, the calibration polynomial's zero-force voltage
        (:func:`slipkit.families.fsr.physics.rest_voltage`, 4.5 V by default; the paper's
        falling wiring only). With ``input="force"`` the graph's rest force is
        ``F(rest)``. The slip sign and the gate follow the detector's fitted
        ``polarity_``.
    gate : bool
        False leaves the touch gate out: the score is the signed block derivative at
        every block (untouched blocks then get a score, not ``NO_SCORE``); no rest
        level is needed, so there is no ``press_sign`` step.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    DetectorGraph
        Input ``(batch, 2 block, 1)`` voltage samples (V), oldest first; ``score``
        ``(batch,)``: the detector's score at the window's last sample, a block
        end; ``hop = block``, ``first_decision`` the detector's first decided
        sample (14 for 10 rest samples and 5-sample blocks).
    """
    check_is_fitted(detector, "threshold_")
    per_recording = (
        detector.input == "voltage" and detector._polarity == "per_recording"
    )
    # voltage input with the gate: the rest level comes from the stream (press_sign)
    stream_rest = detector.input == "voltage" and gate and rest is None
    if per_recording and rest is not None:
        raise ExportError(
            "FSR export: polarity 'per_recording' takes each recording's rest level "
            "from the stream (the press_sign op); rest=... has no meaning here"
        )
    if per_recording and not gate:
        raise ExportError(
            "FSR export: polarity 'per_recording' needs the touch gate (gate=True): "
            "before its first press a recording has no sign"
        )
    confirm = int(detector.confirm_events) > 1
    if confirm and not gate:
        raise ExportError(
            "FSR export: the confirmed variant (confirm_events > 1) needs the touch gate "
            "(gate=True): its batch form only counts touched blocks"
        )
    b = int(detector.block)
    gap, wb = detector._peak_gap, detector._confirm_blocks
    # confirmed: the blocks whose derivative a peak in the window needs (wb candidates,
    # gap on each side) plus the first one's predecessor
    n_blocks = wb + 2 * gap + 1 if confirm else 2
    w = n_blocks * b
    polarity = detector._polarity
    # rest from the stream: the press_sign op feeds sign * (v - rest), a falling-wiring
    # signal at rest 0, so the graph is the paper's with slip sign +1 and rest 0
    sign = 1.0 if stream_rest else detector._sign
    per_s = detector._per_s
    delta = float(getattr(detector, "delta_", detector._delta))
    coeffs = detector._coeffs() if detector.input == "force" else None
    fitted_rest = float(getattr(detector, "rest_V_", math.nan))
    if stream_rest:
        v_rest = 0.0
    elif rest is not None:
        v_rest = float(rest)
    elif math.isfinite(fitted_rest):
        v_rest = fitted_rest
    elif polarity == "falling":
        v_rest = float(rest_voltage(tuple(detector._coeffs().tolist())))
    else:
        raise ExportError(
            "FSR export: the detector has no measured rest voltage (rest_V_) and the "
            "calibration's zero-force voltage assumes the falling wiring; pass rest=..."
        )
    if not math.isfinite(v_rest):
        raise ExportError(
            f"FSR export: rest must be a finite voltage (V); got {rest!r}"
        )
    rest_sig = v_rest if coeffs is None else float(np.polyval(coeffs, v_rest))

    g = GraphBuilder("fsr_touch_slip", opset)
    # float64 in and out: the runtime feeds the float64 window the batch detector
    # reads (no cast node, no float32 rounding), and reads a float64 score (no clip to
    # the float32 range, no cast back). One channel: the window is (batch, w).
    inp = helper.make_tensor_value_info(WINDOW_INPUT, DOUBLE, ["batch", w])
    v = WINDOW_INPUT
    if coeffs is not None:
        # eq. 6 by Horner's rule, as numpy.polyval evaluates it
        acc = g.op("Mul", v, g.const(coeffs[0], np.float64))
        for p in coeffs[1:-1]:
            acc = g.op("Mul", g.op("Add", acc, g.const(p, np.float64)), v)
        v = g.op("Add", acc, g.const(coeffs[-1], np.float64), stem="force")
    if not confirm and gate:
        score64 = _fsr_gated(g, v, b, w, sign * per_s, sign, delta - sign * rest_sig)
    else:
        if confirm:
            score = _fsr_confirmed(g, v, detector, n_blocks, rest_sig, delta, sign)
        else:
            deriv = g.op(
                "MatMul", v, g.const(_fsr_deriv_row(b, w, sign * per_s), np.float64)
            )  # (batch,)
            ok = g.op("Not", _not_finite(g, deriv), stem="finite")
            score = g.op("Where", ok, deriv, g.const(NO_SCORE, np.float64))
        score64 = _float32_range(g, score)
    return _fsr_graph_out(
        g,
        inp,
        score64,
        detector,
        w,
        v_rest,
        rest_sig,
        delta,
        gate,
        polarity,
        sign,
        stream_rest=stream_rest,
    )


#: The gated FSR graph's gate column is ``_GATE_SCALE * (press - delta')``: a power of
#: two, so the scaling is exact (float64 rounding commutes with it), and large enough
#: that any press above the gate by 2**-400 or more (every press of a voltage or force
#: above 1e-100, as the gate's own spacing is) lands far above every score.
_GATE_SCALE = 2.0**600
#: Subtracted from the gate column: a press at or below the gate (column <= 0) lands
#: below NO_SCORE (-3.4e38 > -2**128), a press above it (column >= 2**200) stays above
#: every block derivative below 2**199.
_GATE_SHIFT = 2.0**128


def _float32_range(g: GraphBuilder, score: str) -> str:
    # The float64 score within the float32 range, NO_SCORE at the bottom: a decision
    # sink packs it as float32 (runtime/sinks.py), and below NO_SCORE it would read as
    # "cannot decide" anyway.
    return g.op(
        "Clip",
        score,
        g.const(NO_SCORE, np.float64),
        g.const(_F32_MAX, np.float64),
        stem="score64",
    )


def _fsr_deriv_row(b: int, w: int, scale: float) -> NDArray[np.float64]:
    """``(w,)`` weights of ``scale * (mean(last block) - mean(previous block))``."""
    row = np.zeros(w)
    row[:b] = -scale / b
    row[b:] = scale / b
    return row


def _fsr_gated(
    g: GraphBuilder,
    v: str,
    b: int,
    w: int,
    deriv_scale: float,
    sign: float,
    gate: float,
) -> str:
    """The two-block score with the touch gate in four nodes: ``(batch,)`` float64.

    ``deriv = deriv_scale (mean(last) - mean(previous))``; touched where ``press =
    -sign mean(last) > gate``. Node dispatch, not arithmetic, is a batch-1 call's
    cost, and ``Where`` and ``Split`` were the dearest small kernels in scratch
    timings (several times an elementwise op), so the gate is a minimum instead: one ``Gemm`` gives ``[u, deriv]`` with ``u = K (press - gate)``
    (``K`` = :data:`_GATE_SCALE`, exact), ``Add`` shifts ``u`` down by
    :data:`_GATE_SHIFT`, ``ReduceMin`` over the two columns is ``deriv`` when touched
    (``u >= 2**200 - 2**128``) and below :data:`NO_SCORE` when not (``u <=
    -2**128``; ``press == gate`` is untouched, as in the batch detector), and
    ``Clip`` lifts the latter to exactly ``NO_SCORE`` (and keeps a derivative
    within the float32 range, as a decision sink packs it). The zero gate weights on the
    previous block turn a NaN or inf anywhere in the window into NaN in ``u`` (0 *
    NaN = 0 * inf = NaN), and ``ReduceMin`` keeps a NaN in its first column: a
    non-finite window scores NaN (or ``NO_SCORE`` where ``u`` or ``deriv`` is
    ``-inf``), never a finite score; the runtime loop never calls the graph on one.
    """
    weights = np.zeros((w, 2))
    weights[b:, 0] = -sign * _GATE_SCALE / b
    weights[:, 1] = _fsr_deriv_row(b, w, deriv_scale)
    bias = np.array([-_GATE_SCALE * gate, 0.0])
    if not np.isfinite(bias).all():
        raise ExportError(
            f"FSR export: the touch gate {gate!r} (V or N) is not a finite number below 2**424"
        )
    stats = g.op("Gemm", v, g.const(weights, np.float64), g.const(bias, np.float64))
    shifted = g.op(
        "Add", stats, g.const([-_GATE_SHIFT, 0.0], np.float64), stem="gate_deriv"
    )
    if g.opset >= 18:
        low = g.op("ReduceMin", shifted, _axes(g, 1), keepdims=0, stem="gated")
    else:
        low = g.op("ReduceMin", shifted, axes=[1], keepdims=0, stem="gated")
    return _float32_range(g, low)


#: Below every finite block score: the confirmed graph's "no derivative here" (the batch
#: detector's -inf), finite so that maxima and comparisons never meet inf - inf.
_NO_BLOCK = -1e300


def _fsr_confirmed(
    g: GraphBuilder,
    v: str,
    detector: FSRTouchSlip,
    n_blocks: int,
    rest_sig: float,
    delta: float,
    sign: float,
) -> str:
    """Nodes of the confirmed score: the ``confirm_events``-th largest derivative peak
    among the ``_confirm_blocks`` candidates of the window (``FSRTouchSlip._confirmed``);
    ``sign`` is the slip direction of the graph's input (+1: rising)."""
    b, gap, wb = int(detector.block), detector._peak_gap, detector._confirm_blocks
    k = int(detector.confirm_events)
    nd = n_blocks - 1  # block derivatives in the window, oldest first
    blocks = g.op("Reshape", v, g.const([-1, n_blocks, b], np.int64), stem="blocks")
    means = g.op(
        "Div",
        g.op("ReduceSum", blocks, _axes(g, 2), keepdims=0),
        g.const(float(b), np.float64),
        stem="means",
    )  # (batch, n_blocks)

    def cols(t: str, start: int, stop: int) -> str:
        i64 = np.int64
        return g.op(
            "Slice", t, g.const([start], i64), g.const([stop], i64), _axes(g, 1)
        )

    last = cols(means, 1, n_blocks)
    deriv = g.op(
        "Mul",
        g.op("Sub", last, cols(means, 0, nd)),
        g.const(sign * float(detector._per_s), np.float64),
        stem="deriv",
    )  # (batch, nd)
    press = g.op(
        "Mul",
        g.op("Sub", g.const(rest_sig, np.float64), last),
        g.const(sign, np.float64),
        stem="press",
    )
    ok = g.op(
        "And",
        g.op("Not", _not_finite(g, deriv)),
        g.op("Greater", press, g.const(delta, np.float64)),
        stem="touched_finite",
    )
    d = g.op("Where", ok, deriv, g.const(_NO_BLOCK, np.float64), stem="block_score")
    # max over each run of `gap` blocks: m[j] = max(d[j .. j + gap - 1])
    run_max = g.op(
        "Reshape",
        g.op(
            "MaxPool",
            g.op("Unsqueeze", d, _axes(g, 1)),
            kernel_shape=[gap],
            strides=[1],
        ),
        g.const([-1, nd - gap + 1], np.int64),
        stem="run_max",
    )
    # candidates j = gap .. gap + wb - 1: left = m[j - gap], right = m[j + 1]
    mid = cols(d, gap, gap + wb)
    left = cols(run_max, 0, wb)
    right = cols(run_max, gap + 1, gap + 1 + wb)
    # near-equal neighbours are ties (FSRTouchSlip._peak_tie), so float32 input
    # rounding never moves a peak; _NO_BLOCK +- tie is still _NO_BLOCK
    tie = float(detector._peak_tie)
    peak = g.op(
        "And",
        g.op("Greater", mid, g.op("Add", left, g.const(tie, np.float64))),
        g.op("GreaterOrEqual", mid, g.op("Sub", right, g.const(tie, np.float64))),
        stem="peak",
    )
    pv = g.op("Where", peak, mid, g.const(_NO_BLOCK, np.float64), stem="peak_score")
    top, idx = g._fresh("top"), g._fresh("top_idx")
    g.nodes.append(
        helper.make_node(
            "TopK",
            [pv, g.const([k], np.int64)],
            [top, idx],
            axis=1,
            largest=1,
            sorted=1,
        )
    )
    kth = g.op("Reshape", cols(top, k - 1, k), g.const([-1], np.int64), stem="kth")
    return g.op(
        "Where",
        g.op("Greater", kth, g.const(_NO_BLOCK, np.float64)),
        kth,
        g.const(NO_SCORE, np.float64),
        stem="score64",
    )


def _fsr_graph_out(
    g: GraphBuilder,
    inp: onnx.ValueInfoProto,
    score64: str,
    detector: FSRTouchSlip,
    w: int,
    v_rest: float,
    rest_sig: float,
    delta: float,
    gate: bool,
    polarity: str,
    sign: float,
    *,
    stream_rest: bool,
) -> DetectorGraph:
    b = int(detector.block)
    per_recording = polarity == "per_recording" and detector.input == "voltage"
    confirm = int(detector.confirm_events) > 1
    unit = "V/s" if detector.input == "voltage" else "N/s"
    what = (
        f"the {detector.confirm_events}-th largest derivative peak of the "
        f"{detector._confirm_blocks} blocks before the last {detector._peak_gap}"
        if confirm
        else f"signed derivative of the last two {b}-sample block means"
    )
    against = (
        "the recording's own rest level, sign-normalised by the press_sign op"
        if stream_rest
        else f"v_rest = {v_rest:g} V"
    )
    # float64 out: the last node writes the score itself
    last = g.nodes[-1]
    assert list(last.output) == [score64]
    last.output[0] = SCORE
    model = g.build(
        [inp],
        [helper.make_tensor_value_info(SCORE, DOUBLE, ["batch"])],
        doc=f"FSRTouchSlip ({detector.input}) over {w} samples: {what} ({unit})"
        + (f", NO_SCORE unless touched against {against}" if gate else ""),
    )
    import scipy

    graph = _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=1,
        hop=b,
        first_decision=detector._first_block * b + b - 1,
        score_meaning=(
            "FSRTouchSlip.decision_function at the window's last sample (a block end): "
            + (
                "the derivative, against the recording's own press, of the block "
                if per_recording
                else f"{'rising' if detector._sign > 0 else 'falling'} {detector.input} "
                "derivative of the block "
            )
            + f"means ({unit}); {NO_SCORE:g} (the detector's -inf) "
            + ("when untouched or " if gate else "")
            + "on non-finite samples; slip ('1') where score >= threshold"
        ),
        input_meaning=(
            f"the last {w} FSR voltage samples (V) at {detector.rate_hz:g} Hz, oldest "
            "first"
            + (
                ", after press_sign: sign * (v - v_rest) with the recording's own rest "
                "and press direction (0 before its first press)"
                if per_recording
                else (
                    f", after press_sign: {detector._sign:+g} * (v - v_rest) with the "
                    "recording's own rest (0 until its rest period has passed)"
                )
                if stream_rest
                else ""
            )
        ),
        features={
            "input": detector.input,
            "polarity": polarity,
            "confirm_events": int(detector.confirm_events),
            "confirm_blocks": int(detector._confirm_blocks) if confirm else 0,
            "peak_gap_blocks": int(detector._peak_gap) if confirm else 0,
            "block": b,
            "rate_hz": float(detector.rate_hz),
            "gate": bool(gate),
            # None: the rest level comes from the stream (the press_sign step)
            "rest_V": None if stream_rest else v_rest,
            "rest_signal": rest_sig,
            "delta": delta,
        },
        scipy=scipy.__version__,
    )
    graph = replace(graph, input_shape=("batch", w), input_dtype="float64")
    if not stream_rest:
        return graph
    return replace(graph, preprocessing=(fsr_press_sign_step(detector),))


def fsr_press_sign_step(detector: FSRTouchSlip) -> dict[str, Any]:
    """The runtime step that takes a recording's rest level from its stream (``press_sign``).

    For a fitted voltage-input :class:`FSRTouchSlip`: the rest level is the mean of
    the recording's first ``rest_samples`` finite samples, as the batch detector's
    (``FSRTouchSlip._block_stats``). A fixed ``polarity_`` gives the step's ``sign``
    (+1 falling, -1 rising: the slip sign of the voltage); with ``"per_recording"``
    the sign is 0, and the first block mean (of ``block`` samples, from the first
    block after the rest period) further than ``delta`` (V) from rest sets it, as the
    batch detector does. The graph's calls are every ``block`` samples.
    """
    check_is_fitted(detector, "threshold_")
    if detector.input != "voltage":
        raise ExportError(
            "FSR export: the press_sign step reads the voltage; a force-input detector "
            "keeps its rest force in the graph"
        )
    step: dict[str, Any] = {
        "op": "press_sign",
        "rest_frames": int(detector.rest_samples),
        "block": int(detector.block),
        "hop": int(detector.block),
        "delta": float(getattr(detector, "delta_", detector._delta)),
    }
    if detector._polarity != "per_recording":
        step["sign"] = int(detector._sign)
    return step


def fsr_runtime_steps(det: FSRTouchSlip, ctx: StreamContext) -> RuntimeSteps:
    """A voltage-input detector: the ``press_sign`` step on the gripper PC.

    The runtime takes each stream's rest level from its first samples, as the batch
    detector does per recording, so a stream of the other wiring is never touched;
    with training wirings of both signs the press direction is latched at its first
    press too. The graph reads the sign-normalised signal.
    """
    del ctx
    if det.input != "voltage":
        return RuntimeSteps()
    step = fsr_press_sign_step(det)
    sign = (
        f"wiring sign (its first block mean further than {step['delta']:g} V "
        "from rest), as the detector's per-recording polarity"
        if "sign" not in step
        else f"the fitted polarity's sign ({det.polarity_})"
    )
    return RuntimeSteps(
        steps=[step],
        notes=[
            "press_sign: the stream's rest level (mean of its first "
            f"{det.rest_samples} samples) and {sign}, latched on the gripper "
            "PC; start the loop (or reset it) at rest before each grasp"
        ],
    )


def fsr_gate_margin(
    detector: FSRTouchSlip,
    graph: DetectorGraph,
    x: NDArray[np.float64],
    inst: NDArray[np.int64],
) -> tuple[NDArray[np.float64], float]:
    """|press - delta| of the batch detector at ``inst`` and |graph rest - recording rest|
    (the parity check's gate margin, :func:`slipkit.export.detector_parity.register_gate_margin`).

    With the rest from the stream (``press_sign``) no rest differs, and the gap is one
    float32 step of the largest ``|v - rest|`` (far above the few float64 steps by which
    the graph's block sums and numpy's means differ).
    """
    spec = graph.features or {}
    b = int(spec["block"])
    if any(st.get("op") == "press_sign" for st in graph.preprocessing):
        # the press_sign op gives the graph this recording's own rest (and, per
        # recording, its sign): the batch detector's press per block, at the instants
        # (block ends)
        _, press_b = detector._block_stats(x[:, 0])
        blk = (inst - (b - 1)) // b
        press_i = np.full(len(inst), np.nan)
        ok = blk < len(press_b)
        press_i[ok] = press_b[blk[ok]]
        # the graph reads sign * (v - rest) in float64 and sums a block in its own
        # order: its press can differ from numpy's mean by a few float64 steps of the
        # largest |v - rest|; allow one float32 step, far above that (no rest gap: the
        # rest is the same)
        head = x[: int(detector.rest_samples), 0]
        finite = head[np.isfinite(head)]
        dev = np.abs(x[:, 0] - np.mean(finite)) if finite.size else np.zeros(1)
        top = float(np.max(dev[np.isfinite(dev)], initial=0.0))
        return np.abs(press_i - float(spec["delta"])), float(
            np.spacing(np.float32(min(top, _F32_MAX)))
        )
    sig = detector._signal(x[:, 0])
    head = sig[: int(detector.rest_samples)]
    finite = head[np.isfinite(head)]
    rest = float(np.mean(finite)) if finite.size else np.nan
    means = sliding_window_view(sig, b).mean(axis=1)[inst - (b - 1)]
    press = detector._sign * (rest - means)
    return np.abs(press - float(spec["delta"])), abs(float(spec["rest_signal"]) - rest)


register_exporter(FSRTouchSlip, export_fsr_touch_slip)
register_runtime_steps(FSRTouchSlip, fsr_runtime_steps)
register_gate_margin(FSRTouchSlip, fsr_gate_margin)
