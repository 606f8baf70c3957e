"""Exporters of the analytic detectors whose math ONNX can express: a window in, the score out.

Every graph takes a window of the last ``W`` raw samples, shape ``(batch, W,
n_channels)`` float32, oldest first (what the runtime's ring buffer holds), and
returns ``score`` ``(batch,)`` float32: the detector's
:meth:`~slipkit.baselines.base.StreamDetector.decision_function` at the window's
last sample. The decision is slip where ``score >= threshold_`` (non-strict, as
every :class:`~slipkit.baselines.base.StreamDetector`); :class:`DetectorGraph`
defaults ``strict`` to False, where the registry's
:class:`~slipkit.export.registry.ExportedGraph` defaults to True (scikit-learn's
``predict``). Inside, every graph casts the window to float64, so
the only rounding that differs from the batch detector is the float32 input. The FSR
graphs instead read the float64 window itself, shape ``(batch, W)`` (one channel), and
return a float64 score: no cast nodes, no float32 rounding.

* :class:`~slipkit.baselines.fsr.FSRTouchSlip` -- ``W = 2 block`` (10): the two
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
* :class:`~slipkit.baselines.biotac.ForceDerivative` -- ``W = span + 1`` (4):
  ``Ft = sqrt(fx^2 + fy^2)`` (or ``Ft`` itself) at both ends, ``-(Ft[-1] - Ft[0])
  rate / span``; the same numbers as the batch detector.
* :class:`~slipkit.baselines.biotac.PressureVibration` -- the IIR band-pass as one
  MatMul over ``W = L + window - 1`` samples (:func:`steady_state_fir`), rectify,
  ``TopK`` for the ``n_exceed``-th largest of the last ``window`` outputs, over a
  **fixed baseline** (the detector's ``baseline`` option).
* :class:`~slipkit.baselines.sliptack.TorsionalSlipDetector` -- the band-pass as in
  the pressure graph, then the RMS of the last ``window`` outputs.

Windowed IIR filters (:func:`steady_state_fir`): the graph filters its window with
the state a constant input equal to the window's first sample would leave
(``sosfilt_zi``), which is what the batch detector does at a recording's start.
Later, the batch output also carries the response to samples before the window;
with ``h`` the impulse response and ``T(L) = sum_{m >= L} |h[m]|`` its tail, every
graph output differs from the batch one by at most ``T(L) D`` where ``D`` is the
largest deviation of an earlier sample from the window's first one. ``L`` is the
smallest length with ``T(L) <= tail_tol``.

Parity (:func:`check_detector_parity`) compares the graph on the windows the runtime
feeds (float32, float64 for FSR) with
the batch detector on the recordings, at the instants the runtime would call it;
``python -m slipkit.export.detectors`` prints it (and the time per call) for every
detector on simulated recordings.

Where the detector scores ``-inf`` (cannot decide: warm-up, untouched, missing
data) a graph scores :data:`NO_SCORE`, the lowest float32 (below any threshold),
because the runtime loop skips non-finite scores instead of deciding "no slip";
:func:`graph_scores` reads it back as ``-inf``.

NaN policy (graphs): a window holding a NaN or inf scores ``NO_SCORE`` (never slip;
the two-block FSR graph with the gate: NaN or ``NO_SCORE``, never a finite score),
except where the batch detector provably ignores the sample (the middle samples of
the force-derivative window). FSR and force derivative then agree with their batch
detectors exactly; the pressure detector's batch form instead holds the last finite
value and scores only the missing sample ``-inf``, so after a dropped sample the
graph stays silent for ``W`` samples (conservative; a sample-and-hold needs a
running maximum ONNX does not have; the runtime loop skips windows holding a
non-finite frame anyway). The torsional detector replaces NaN by 0 in
the graph, as its batch form (``numpy.nan_to_num``) does.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import onnx
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from onnx import helper
from scipy.signal import sosfilt, sosfilt_zi
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import StreamDetector, segment_bounds
from slipkit.baselines.biotac import ForceDerivative, PressureVibration
from slipkit.baselines.fsr import FSRTouchSlip
from slipkit.baselines.sliptack import TorsionalSlipDetector
from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.parity import DEFAULT_EPS_REL, MIN_AGREEMENT, onnx_session
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    ExportError,
    producers,
    register_exporter,
)
from slipkit.physics.fsr import rest_voltage

WINDOW_INPUT = "window"
SCORE = "score"
#: Default tail tolerance ``T(L)`` of the windowed band-pass filters (output units
#: per input unit of deviation): 1e-5 x a 300-count swing is 0.003 counts.
DEFAULT_TAIL_TOL = 1e-5
#: The graphs' score where the detector scores ``-inf`` (cannot decide: untouched,
#: warm-up, non-finite samples): the lowest float32, below any threshold. Finite
#: because the runtime loop skips a window whose score is not finite (its sign of a
#: float32 overflow) instead of recording a no-slip decision.
NO_SCORE = float(np.finfo(np.float32).min)
_F32_MAX = float(np.finfo(np.float32).max)
_MAX_TAPS = 1 << 17


@dataclass(frozen=True)
class DetectorGraph(ExportedGraph):
    """An :class:`ExportedGraph` of a windowed analytic detector.

    Parameters
    ----------
    window : int
        Samples per graph call (``input_shape[1]``), oldest first.
    hop : int
        Samples between calls: the runtime calls the graph when the window is first
        full (sample ``window - 1``) and every ``hop`` samples after, counted from
        the recording's first sample (the runtime loop's ``frame.hop``).
    preprocessing : tuple of dict
        Runtime op steps (:data:`slipkit.runtime.preprocessing.OPS`) that turn the
        raw window into the graph's input (the manifest's ``preprocessing``); empty:
        the graph reads the raw samples. Stateful steps see every runtime call of a
        recording from its first, in order.
    first_decision : int
        0-based sample of the recording at which the batch detector first decides
        (its warm-up ends); earlier calls have no batch counterpart.
    strict : bool
        As in :class:`~slipkit.export.registry.ExportedGraph`; False here
        (``score >= threshold``, every StreamDetector).
    """

    window: int = 1
    hop: int = 1
    first_decision: int = 0
    strict: bool = False
    preprocessing: tuple[dict[str, Any], ...] = ()
    prepare: onnx.ModelProto | None = None
    prepare_tensor: str = ""

    def serialize_prepare(self) -> bytes | None:
        """The prepare graph's ONNX bytes (None without one)."""
        return None if self.prepare is None else bytes(self.prepare.SerializeToString())

    def prepare_session(self) -> Any:
        """An onnxruntime session of the prepare graph (CPU, one thread)."""
        assert self.prepare is not None
        return onnx_session(replace(self, model=self.prepare, prepare=None))

    def run_windows(
        self, session: Any, windows: NDArray[Any], prepare_session: Any = None
    ) -> NDArray[Any]:
        """The score output on a batch of graph inputs ``windows`` (as the runtime calls it).

        With a ``prepare`` graph, each call's prepared tensor comes from the window one
        sample earlier (the window less its newest sample, behind a row the prepare
        graph drops), as the runtime runs it on the frame before a decision.
        ``prepare_session``: reuse a session of the prepare graph (else CPU, one thread).
        """
        feed = {self.input_name: windows}
        if self.prepare is not None:
            if prepare_session is None:
                prepare_session = self.prepare_session()
            earlier = np.concatenate([windows[:, :1], windows[:, :-1]], axis=1)
            feed[self.prepare_tensor] = prepare_session.run(
                [self.prepare_tensor], {self.input_name: earlier}
            )[0]
        return np.asarray(session.run([self.score_output], feed)[0])

    def describe(self) -> dict[str, Any]:
        """The registry's description plus ``frame`` (window, hop, first_decision)
        and the runtime ``preprocessing`` steps the graph needs before it."""
        out = super().describe()
        out["frame"] = {
            "window": self.window,
            "hop": self.hop,
            "first_decision": self.first_decision,
        }
        out["preprocessing"] = [dict(s) for s in self.preprocessing]
        if self.prepare is not None:
            out["prepare"] = {"tensor": self.prepare_tensor}
        return out

    def instants(self, n: int) -> NDArray[np.int64]:
        """Samples of an ``n``-sample recording at which the runtime calls the graph
        and the batch detector decides (0-based, the window's last sample)."""
        start = self.window - 1
        if self.first_decision > start:
            # the first call at or after the warm-up, on the hop grid
            start += -(-(self.first_decision - start) // self.hop) * self.hop
        return np.arange(start, n, self.hop, dtype=np.int64)


# -- shared graph pieces -------------------------------------------------------------
def _prologue(
    g: GraphBuilder, window: int, channels: int
) -> tuple[onnx.ValueInfoProto, str]:
    inp = helper.make_tensor_value_info(
        WINDOW_INPUT, FLOAT, ["batch", window, channels]
    )
    # float64 inside: the float32 input is then the only rounding the batch lacks.
    return inp, g.op("Cast", WINDOW_INPUT, to=DOUBLE, stem="x64")


def _axes(g: GraphBuilder, *axes: int) -> str:
    return g.const(list(axes), np.int64, stem="axes")


def _not_finite(g: GraphBuilder, v: str) -> str:
    # v - v is NaN exactly for NaN and +-inf (the trick slipkit.export.pins uses).
    return g.op("IsNaN", g.op("Sub", v, v), stem="not_finite")


def _finish(
    g: GraphBuilder,
    inp: onnx.ValueInfoProto,
    score64: str,
    doc: str,
) -> onnx.ModelProto:
    # Clip before the cast: a float64 score beyond the float32 range would become
    # +-inf; below NO_SCORE it would read as "cannot decide" anyway.
    clipped = g.op(
        "Clip",
        score64,
        g.const(NO_SCORE, np.float64),
        g.const(_F32_MAX, np.float64),
        stem="clipped",
    )
    g.nodes.append(helper.make_node("Cast", [clipped], [SCORE], to=FLOAT))
    return g.build(
        [inp], [helper.make_tensor_value_info(SCORE, FLOAT, ["batch"])], doc=doc
    )


def _graph(
    detector: StreamDetector,
    model: onnx.ModelProto,
    *,
    opset: int,
    window: int,
    channels: int,
    hop: int,
    first_decision: int,
    score_meaning: str,
    input_meaning: str,
    features: dict[str, Any],
    **extra_producers: str,
) -> DetectorGraph:
    return DetectorGraph(
        model=model,
        input_name=WINDOW_INPUT,
        input_shape=("batch", window, channels),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning=score_meaning,
        score_method="decision_function",
        opset=opset,
        classes=tuple(str(c) for c in detector.classes_),
        threshold=float(detector.threshold_),
        input_meaning=input_meaning,
        features={
            "kind": "detector_window",
            "detector": type(detector).__name__,
            **features,
        },
        producers=producers(**extra_producers),
        window=window,
        hop=hop,
        first_decision=first_decision,
        strict=False,
    )


def steady_state_fir(
    sos: ArrayLike, n_out: int, *, tail_tol: float = DEFAULT_TAIL_TOL
) -> tuple[NDArray[np.float64], float]:
    """The windowed IIR filter as one matrix: ``y_last = x @ M``.

    Parameters
    ----------
    sos : array_like (n_sections, 6)
        The filter (``scipy.signal`` second-order sections).
    n_out : int
        Outputs wanted: the filter's last ``n_out`` samples over the window.
    tail_tol : float
        Largest tail ``T(L) = sum_{m >= L} |h[m]|`` of the impulse response ``h``
        (``scipy.signal.sosfilt`` of a unit impulse) left out.

    Returns
    -------
    M : ndarray (W, n_out)
        ``W = L + n_out - 1`` with ``L`` the smallest length such that
        ``T(L) <= tail_tol``. Row ``i`` is the filter's response to sample ``i``
        with the initial state of a constant input equal to the window's first
        sample (``sosfilt_zi``), so ``x @ M`` equals ``sosfilt(sos, x,
        zi=sosfilt_zi(sos) * x[0])[-n_out:]`` up to rounding, and the true output of a
        longer recording within ``T(L)`` times the largest deviation of earlier
        samples from ``x[0]``.
    tail : float
        ``T(L)`` achieved.
    """
    s = np.asarray(sos, dtype=np.float64)
    if not tail_tol > 0:
        raise ExportError(f"tail_tol must be > 0; got {tail_tol!r}")
    n = 4096
    while True:
        impulse = np.zeros(n)
        impulse[0] = 1.0
        h = np.abs(sosfilt(s, impulse))
        tail = np.cumsum(h[::-1])[::-1]  # tail[L] = sum_{m >= L} |h[m]|
        below = np.flatnonzero(tail <= tail_tol)
        # Trust the tail only when the impulse ran well past it (the rest is smaller).
        if below.size and below[0] < n // 2:
            taps = int(below[0])
            break
        if n >= _MAX_TAPS:
            raise ExportError(
                f"the filter's impulse response does not decay below tail_tol={tail_tol:g} "
                f"within {_MAX_TAPS} samples (tail {tail[n // 2]:.3g} at {n // 2})"
            )
        n *= 2
    taps = max(taps, 1)
    w = taps + int(n_out) - 1
    zi = np.zeros((s.shape[0], w, 2))
    zi[:, 0, :] = sosfilt_zi(s)  # only sample 0 sets the initial (steady) state
    y, _ = sosfilt(s, np.eye(w), axis=-1, zi=zi)
    return np.ascontiguousarray(y[:, w - int(n_out) :]), float(tail[taps])


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
        (:func:`slipkit.physics.fsr.rest_voltage`, 4.5 V by default; the paper's
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


# -- BioTac force derivative --------------------------------------------------------------
def export_force_derivative(
    detector: ForceDerivative, *, opset: int = DEFAULT_OPSET
) -> DetectorGraph:
    """Export a fitted :class:`ForceDerivative` over a window of ``span + 1`` samples.

    Parameters
    ----------
    detector : ForceDerivative
        Fitted on ``Ft`` (1 channel) or ``(Fx, Fy)`` (2 channels, N).
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    DetectorGraph
        Input ``(batch, span + 1, n_channels)`` forces (N), oldest first; ``score``
        ``(batch,)`` = ``-(Ft[-1] - Ft[0]) rate_hz / span`` (N/s), ``NO_SCORE`` where
        either end is not finite; hop 1.
    """
    check_is_fitted(detector, "threshold_")
    s = int(detector.span)
    w = s + 1
    c = int(detector.n_features_in_)
    g = GraphBuilder("force_derivative", opset)
    inp, x = _prologue(g, w, c)
    if c == 1:
        ft = g.op("Reshape", x, g.const([-1, w], np.int64), stem="ft")
    else:
        # float64 squares of float32 forces cannot overflow, so no hypot is needed
        ft = g.op(
            "Sqrt",
            g.op("ReduceSum", g.op("Mul", x, x), _axes(g, 2), keepdims=0),
            stem="ft",
        )
    first = g.op("Gather", ft, g.const(0, np.int64), axis=1, stem="ft_old")
    last = g.op("Gather", ft, g.const(w - 1, np.int64), axis=1, stem="ft_new")
    d = g.op(
        "Mul",
        g.op("Sub", last, first),
        g.const(-float(detector.rate_hz) / s, np.float64),
        stem="neg_dft",
    )
    score64 = g.op(
        "Where", _not_finite(g, d), g.const(NO_SCORE, np.float64), d, stem="score64"
    )
    model = _finish(g, inp, score64, f"ForceDerivative: -dFt/dt over {s} samples (N/s)")
    channels = "Ft" if c == 1 else "Fx, Fy"
    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=c,
        hop=1,
        first_decision=s,
        score_meaning=(
            "ForceDerivative.decision_function at the window's last sample: -dFt/dt "
            f"(N/s) over {s} samples, {NO_SCORE:g} (the detector's -inf) when an end is "
            "not finite; slip ('1') where "
            "score >= threshold"
        ),
        input_meaning=f"the last {w} samples of {channels} (N) at {detector.rate_hz:g} Hz, oldest first",
        features={"span": s, "rate_hz": float(detector.rate_hz), "channels": c},
    )


# -- BioTac pressure vibration -----------------------------------------------------------
def pressure_baseline(
    detector: PressureVibration, X: ArrayLike, *, segments: ArrayLike | None = None
) -> float:
    """A fixed baseline (counts RMS) for export: the median over recordings of the one
    the batch detector measures (band-passed RMS of the first ``baseline_samples``).

    Parameters
    ----------
    detector : PressureVibration
        Its filter and ``baseline_samples`` are used (fitted or not).
    X : array_like (n_samples, 1)
        Calibration recordings (AC pressure, counts) in time order.
    segments : array_like (n_samples,), optional
        Recording id of every sample.

    Returns
    -------
    float
        The median baseline, at least ``baseline_floor``.
    """
    x = np.asarray(X, dtype=np.float64).reshape(len(np.asarray(X)), -1)[:, 0]
    nb = int(detector.baseline_samples)
    sos = detector._sos
    bases = []
    for a, z in segment_bounds(len(x), segments):
        r = x[a:z]
        r = r[np.isfinite(r)]
        if len(r) < nb:
            continue
        yf = sosfilt(sos, r[:nb], zi=sosfilt_zi(sos) * r[0])[0]
        bases.append(math.sqrt(float(np.mean(yf**2))))
    if not bases:
        raise ExportError(
            f"no calibration recording has {nb} finite samples (baseline_samples) "
            "to measure the pressure baseline on"
        )
    return max(float(np.median(bases)), float(detector.baseline_floor))


def with_fixed_baseline(
    detector: PressureVibration, baseline: float
) -> PressureVibration:
    """The fitted detector with a fixed ``baseline``: the detector a graph deploys.

    A detector trained with ``baseline=None`` divides by each recording's own baseline;
    its graph divides by one constant (:func:`pressure_baseline` of the training
    recordings), so on a recording whose baseline differs the two scores differ by the
    ratio of the baselines (a few % on the simulated lift), not by rounding. Parity is
    a property of the graph and the detector it computes, so the deployer checks the
    graph against this copy and states separately how often it decides as the trained
    detector (:func:`baseline_agreement`).

    Parameters
    ----------
    detector : PressureVibration
        Fitted. Its ``threshold_`` (``k``) is kept as trained, not re-chosen.
    baseline : float
        The fixed baseline (counts RMS).

    Returns
    -------
    PressureVibration
        A deep copy with ``baseline`` set; every fitted attribute as the original.
    """
    check_is_fitted(detector, "threshold_")
    if not (math.isfinite(float(baseline)) and float(baseline) > 0):
        raise ExportError(
            f"baseline must be a positive number of counts; got {baseline!r}"
        )
    out = copy.deepcopy(detector)
    out.baseline = float(baseline)
    return out


def baseline_agreement(
    trained: PressureVibration,
    deployed: PressureVibration,
    X: ArrayLike,
    *,
    segments: ArrayLike | None = None,
) -> tuple[float, int]:
    """How often the deployed (fixed-baseline) detector decides as the trained one.

    Parameters
    ----------
    trained, deployed : PressureVibration
        Fitted; typically ``deployed = with_fixed_baseline(trained, b)``.
    X : array_like (n_samples, 1)
        Recordings (AC pressure, counts) in time order, e.g. the held-out ones.
    segments : array_like (n_samples,), optional
        Recording id of every sample.

    Returns
    -------
    agreement : float
        Fraction of the samples where both detectors decide (finite scores) with the
        same decision; 1.0 when there are none.
    n_samples : int
        Those samples.
    """
    a = trained.decision_function(X, segments=segments)
    b = deployed.decision_function(X, segments=segments)
    both = np.isfinite(a) & np.isfinite(b)
    if not both.any():
        return 1.0, 0
    same = (a[both] >= trained.threshold_) == (b[both] >= deployed.threshold_)
    return float(np.mean(same)), int(both.sum())


def _band_matrix(g: GraphBuilder, v: str, m: NDArray[np.float64]) -> str:
    # One MatMul: ~W x n_out multiply-adds, one BLAS call in onnxruntime.
    return g.op("MatMul", v, g.const(m, np.float64), stem="band")


def export_pressure_vibration(
    detector: PressureVibration,
    *,
    baseline: float | None = None,
    tail_tol: float = DEFAULT_TAIL_TOL,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`PressureVibration` with a fixed baseline.

    Parameters
    ----------
    detector : PressureVibration
        Fitted; ``k = threshold_``.
    baseline : float or None
        Baseline vibration (counts RMS) in the graph. The batch detector measures
        it on the first ``baseline_samples`` of each recording, which no fixed
        window sees, so export fixes it at calibration: None takes the detector's
        own fixed ``baseline`` (fit it with ``baseline=pressure_baseline(...)`` so
        the batch detector and the graph agree), and fails if that is None too.
        Floored at ``baseline_floor`` as the detector does.
    tail_tol : float
        Tail of the band-pass impulse response left out (:func:`steady_state_fir`);
        sets the window ``W``: 1e-5 gives 224 samples (~0.1 s) for 60-700 Hz at
        2.2 kHz.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    DetectorGraph
        Input ``(batch, W, 1)`` AC pressure (counts), oldest first; ``score``
        ``(batch,)``: the ``n_exceed``-th largest rectified band-passed sample of
        the last ``window`` over the baseline; ``NO_SCORE`` when the window holds a
        non-finite sample; hop 1.
    """
    check_is_fitted(detector, "threshold_")
    base = detector.baseline if baseline is None else baseline
    if base is None:
        raise ExportError(
            "PressureVibration with baseline=None measures its baseline per recording, "
            "which a fixed window cannot; export needs a fixed one: refit with "
            "baseline=<counts> (e.g. slipkit.export.detectors.pressure_baseline("
            "detector, X_calibration)) or pass baseline= to the exporter"
        )
    if not (math.isfinite(float(base)) and float(base) > 0):
        raise ExportError(f"baseline must be a positive number of counts; got {base!r}")
    base = max(float(base), float(detector.baseline_floor))
    sos = detector._sos
    n_out, k = int(detector.window), int(detector.n_exceed)
    m, tail = steady_state_fir(sos, n_out, tail_tol=tail_tol)
    w = m.shape[0]

    g = GraphBuilder("pressure_vibration", opset)
    inp, x = _prologue(g, w, 1)
    v = g.op("Reshape", x, g.const([-1, w], np.int64), stem="v")
    bad = _not_finite(g, g.op("ReduceSum", v, _axes(g, 1), keepdims=0))
    rect = g.op("Abs", _band_matrix(g, v, m), stem="rectified")
    top = g._fresh("top")
    g.nodes.append(
        helper.make_node(
            "TopK",
            [rect, g.const([k], np.int64)],
            [top, g._fresh("top_idx")],
            axis=1,
            largest=1,
            sorted=0,
        )
    )
    # the k-th largest is the smallest of the k largest
    kth = _reduce_min(g, top)
    ratio = g.op("Div", kth, g.const(base, np.float64), stem="ratio")
    score64 = g.op("Where", bad, g.const(NO_SCORE, np.float64), ratio, stem="score64")
    lo, hi = (float(f) for f in detector.band_hz)
    model = _finish(
        g,
        inp,
        score64,
        f"PressureVibration: band-pass {lo:g}-{hi:g} Hz as a {w}x{n_out} matrix, "
        f"rectified, {k}-th largest of the last {n_out} over baseline {base:g} counts",
    )
    import scipy

    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=1,
        hop=1,
        first_decision=n_out - 1,
        score_meaning=(
            f"PressureVibration.decision_function at the window's last sample: the "
            f"{k}-th largest rectified band-passed sample of the last {n_out} over the "
            f"fixed baseline ({base:g} counts); {NO_SCORE:g} when the window holds a non-finite "
            "sample; slip ('1') where score >= threshold (k)"
        ),
        input_meaning=f"the last {w} AC-pressure samples (counts) at {detector.rate_hz:g} Hz, oldest first",
        features={
            "baseline": base,
            "band_hz": [lo, hi],
            "order": int(detector.order),
            "filter_window": w,
            "tail_tol": float(tail_tol),
            "tail": tail,
            "n_out": n_out,
            "n_exceed": k,
        },
        scipy=scipy.__version__,
    )


def _reduce_min(g: GraphBuilder, x: str) -> str:
    # ReduceMin takes its axes as an attribute up to opset 17 and as an input from 18.
    if g.opset >= 18:
        return g.op("ReduceMin", x, _axes(g, 1), keepdims=0, stem="kth")
    return g.op("ReduceMin", x, axes=[1], keepdims=0, stem="kth")


# -- SlipTack torsional slip ---------------------------------------------------------------
def export_torsional_slip(
    detector: TorsionalSlipDetector,
    *,
    tail_tol: float = DEFAULT_TAIL_TOL,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`TorsionalSlipDetector`: windowed band-pass, then the RMS.

    Parameters
    ----------
    detector : TorsionalSlipDetector
        Fitted.
    tail_tol : float
        Tail of the band-pass impulse response left out (:func:`steady_state_fir`);
        1e-5 gives ``W = 991`` samples for 5-15 Hz at 1 kHz with the RMS over 100.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    DetectorGraph
        Input ``(batch, W, 1)`` nib signal (e.g. mm), oldest first, NaN read as 0;
        ``score`` ``(batch,)``: RMS of the band over the last ``window`` outputs.
        The batch detector starts its filter at rest (zero state), the graph in the
        steady state of the window's first sample; they agree once the batch
        filter's start transient has decayed, which the tail bound covers from
        sample ``W - 1`` (``first_decision``) on.
    """
    check_is_fitted(detector, "threshold_")
    sos = detector._sos()
    n_out = int(detector.window)
    m, tail = steady_state_fir(sos, n_out, tail_tol=tail_tol)
    w = m.shape[0]
    g = GraphBuilder("torsional_slip", opset)
    inp, x = _prologue(g, w, 1)
    v = g.op("Reshape", x, g.const([-1, w], np.int64), stem="v")
    v = g.op("Where", g.op("IsNaN", v), g.const(0.0, np.float64), v, stem="v_nan0")
    band = _band_matrix(g, v, m)
    ms = g.op(
        "Div",
        g.op("ReduceSum", g.op("Mul", band, band), _axes(g, 1), keepdims=0),
        g.const(float(n_out), np.float64),
        stem="mean_square",
    )
    score64 = g.op("Sqrt", ms, stem="rms")
    lo, hi = (float(f) for f in detector.band_hz)
    model = _finish(
        g,
        inp,
        score64,
        f"TorsionalSlipDetector: RMS over {n_out} samples of the {lo:g}-{hi:g} Hz band "
        f"({w}x{n_out} matrix)",
    )
    import scipy

    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=1,
        hop=1,
        first_decision=w - 1,
        score_meaning=(
            f"TorsionalSlipDetector.decision_function at the window's last sample: RMS "
            f"of the {lo:g}-{hi:g} Hz band over the last {n_out} samples (input unit); "
            "slip ('1') where score >= threshold"
        ),
        input_meaning=f"the last {w} nib samples at {detector.rate_hz:g} Hz, oldest first (NaN: 0)",
        features={
            "band_hz": [lo, hi],
            "order": int(detector.order),
            "filter_window": w,
            "tail_tol": float(tail_tol),
            "tail": tail,
            "n_out": n_out,
        },
        scipy=scipy.__version__,
    )


# -- parity -------------------------------------------------------------------------------
def detector_windows(
    graph: DetectorGraph, X: ArrayLike
) -> tuple[NDArray[np.floating[Any]], NDArray[np.int64]]:
    """The windows the runtime feeds ``graph`` over ONE recording, and their last samples.

    Parameters
    ----------
    graph : DetectorGraph
        The export (its ``window``, ``hop`` and ``first_decision``).
    X : array_like (n_samples, n_channels)
        One recording, raw samples in time order.

    Returns
    -------
    windows : ndarray (n_calls, *graph.input_shape[1:])
        Cut with :func:`numpy.lib.stride_tricks.sliding_window_view` from the
        recording in the graph's input dtype (``graph.input_dtype``: float32, or
        float64 for the FSR graphs), a copy in the graph's input shape (``(window,
        n_channels)``, or ``(window,)`` for the one-channel FSR graphs).
    instants : ndarray (n_calls,) int64
        0-based sample of each window's last sample (:meth:`DetectorGraph.instants`).
    """
    dtype = np.dtype(graph.input_dtype)
    x = np.asarray(X, dtype=dtype)
    if x.ndim == 1:
        x = x[:, None]
    inst = graph.instants(len(x))
    c = x.shape[1]
    shape = tuple(int(s) for s in graph.input_shape[1:])
    if graph.preprocessing and math.prod(shape) != graph.window * c:
        # the steps make the graph input (e.g. sliding_spectrum): raw windows
        shape = (int(graph.window), c)
    if len(inst) == 0:
        return np.empty((0, *shape), dtype=dtype), inst
    view = sliding_window_view(x, (graph.window, c))[:, 0]  # row j = samples j..j+W-1
    out = np.ascontiguousarray(view[inst - (graph.window - 1)])
    return out.reshape(len(inst), *shape), inst


def _preprocessed_windows(
    graph: DetectorGraph, x: NDArray[np.float64], inst: NDArray[np.int64]
) -> NDArray[np.floating[Any]]:
    """The graph inputs at ``inst`` after the graph's runtime ``preprocessing``.

    As :class:`slipkit.runtime.StreamLoop` makes them for one recording: the
    runtime's own :class:`~slipkit.runtime.preprocessing.Pipeline`, fresh, on the
    float64 window of every call from the first (``window - 1``, then every ``hop``),
    in order, so stateful steps see what they would see live; then the graph's input
    dtype (float32 or float64) and shape (e.g. a power spectrum for
    ``sliding_spectrum``).
    """
    from slipkit.runtime.preprocessing import Pipeline

    w, c = graph.window, x.shape[1]
    pipe = Pipeline(list(graph.preprocessing), (w, c), "graph preprocessing")
    calls = np.arange(w - 1, len(x), graph.hop)
    want = {int(i): k for k, i in enumerate(inst)}
    shape = tuple(int(v) for v in graph.input_shape[1:])
    out = np.empty((len(inst), *shape), dtype=np.dtype(graph.input_dtype))
    for end in calls:
        y = pipe(x[end - w + 1 : end + 1])
        k = want.get(int(end))
        if k is not None:
            out[k] = np.reshape(y, shape)
    return out


def graph_scores(out: ArrayLike) -> NDArray[np.float64]:
    """A detector graph's score output as float64 with :data:`NO_SCORE` read as ``-inf``
    (the batch detector's value)."""
    s = np.asarray(out, dtype=np.float64).reshape(-1)
    return np.where(s <= NO_SCORE, -np.inf, s)


def _fsr_gate_margin(
    detector: FSRTouchSlip,
    graph: DetectorGraph,
    x: NDArray[np.float64],
    inst: NDArray[np.int64],
) -> tuple[NDArray[np.float64], float]:
    """|press - delta| of the batch detector at ``inst`` and |graph rest - recording rest|."""
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


def check_detector_parity(
    detector: StreamDetector,
    graph: DetectorGraph,
    X: ArrayLike,
    *,
    segments: ArrayLike | None = None,
    score_eps: float | None = None,
    gate_eps: float | None = None,
    session: Any | None = None,
) -> dict[str, Any]:
    """Compare a detector graph in onnxruntime with the batch detector.

    The batch detector scores the recordings as given (float64); the graph runs on
    the windows the runtime would feed it (:func:`detector_windows`: float32, or
    float64 for the FSR graphs), at
    the instants it would call it (the batch detector's decided samples on the
    runtime's hop grid). Decisions are ``score >= threshold`` on both sides.

    Parameters
    ----------
    detector : StreamDetector
        The fitted detector.
    graph : DetectorGraph
        Its export.
    X : array_like (n_samples, n_channels)
        Held-out recordings in time order.
    segments : array_like (n_samples,), optional
        Recording id of every sample.
    score_eps : float, optional
        Disagreements must lie within this distance of the threshold on the batch
        score. Default: 1e-4 x the largest finite |score|, at least 1e-4.
    gate_eps : float, optional
        FSR graphs with the touch gate: a disagreement also passes when the batch
        detector's ``press`` lies within ``gate_eps`` of ``delta`` (V or N), i.e. the
        gate flipped because the graph's fixed rest differs from the recording's
        rest mean. Default: the largest such difference over the recordings; with the
        rest from the stream (``press_sign``) no rest differs, and the default is one
        float32 step of the largest ``|v - rest|`` (far above the few float64 steps
        by which the graph's block sums and numpy's means differ).
    session : onnxruntime.InferenceSession, optional
        Reuse a session (else CPU, one thread).

    Returns
    -------
    dict
        ``n_frames`` (compared instants), ``agreement``, ``n_disagree``,
        ``max_abs_diff`` and ``max_rel_diff`` (over instants where both scores are
        finite), ``n_finite_mismatch`` (one score finite, the other not),
        ``score_eps``, ``gate_eps`` (None without a gate),
        ``disagreements_near_threshold``, ``has_decisions`` (True) and ``passed``
        (agreement >= 99.9 % and every disagreement near the threshold).
    """
    check_is_fitted(detector, "threshold_")
    if not isinstance(graph, DetectorGraph):
        raise ExportError(
            "check_detector_parity needs a DetectorGraph (slipkit.export.detectors); "
            f"got {type(graph).__name__}: use slipkit.export.check_parity for estimators"
        )
    Xv = np.asarray(X, dtype=np.float64)
    if Xv.ndim == 1:
        Xv = Xv[:, None]
    ref_all = detector.decision_function(Xv, segments=segments)
    sess = session if session is not None else onnx_session(graph)
    prep = graph.prepare_session() if graph.prepare is not None else None
    gated = bool((graph.features or {}).get("gate")) and isinstance(
        detector, FSRTouchSlip
    )
    refs, ours, gates = [], [], []
    rest_gap = 0.0
    for a, z in segment_bounds(len(Xv), segments):
        windows, inst = detector_windows(graph, Xv[a:z])
        if len(inst) == 0:
            continue
        if graph.preprocessing:
            windows = _preprocessed_windows(graph, Xv[a:z], inst)
        out = graph.run_windows(sess, windows, prep)
        ours.append(graph_scores(out))
        refs.append(ref_all[a + inst])
        if gated:
            assert isinstance(detector, FSRTouchSlip)
            gm, gap = _fsr_gate_margin(detector, graph, Xv[a:z], inst)
            gates.append(gm)
            rest_gap = max(rest_gap, gap) if math.isfinite(gap) else rest_gap
    if not refs:
        raise ExportError(
            f"parity needs a recording of at least {graph.instants(10**9)[0] + 1} samples; "
            "none is that long"
        )
    ref, mine = np.concatenate(refs), np.concatenate(ours)
    thr = float(detector.threshold_)
    disagree = (ref >= thr) != (mine >= thr)
    finite_ref = ref[np.isfinite(ref)]
    scale = float(np.max(np.abs(finite_ref))) if finite_ref.size else 0.0
    eps = (
        max(DEFAULT_EPS_REL * scale, DEFAULT_EPS_REL)
        if score_eps is None
        else float(score_eps)
    )
    with np.errstate(invalid="ignore"):
        near = np.abs(ref - thr) <= eps
    g_eps: float | None = None
    if gated:
        g_eps = rest_gap if gate_eps is None else float(gate_eps)
        near |= np.concatenate(gates) <= g_eps
    both = np.isfinite(ref) & np.isfinite(mine)
    diff = np.abs(ref[both] - mine[both])
    max_abs = float(diff.max()) if diff.size else 0.0
    agreement = 1.0 - float(np.mean(disagree))
    ok_near = bool(np.all(near[disagree]))
    return {
        "n_frames": len(ref),
        "agreement": agreement,
        "n_disagree": int(np.sum(disagree)),
        "max_abs_diff": max_abs,
        "max_rel_diff": max_abs / scale if scale > 0 else max_abs,
        "n_finite_mismatch": int(np.sum(np.isfinite(ref) != np.isfinite(mine))),
        "score_eps": eps,
        "gate_eps": g_eps,
        "disagreements_near_threshold": ok_near,
        "has_decisions": True,
        "passed": bool(agreement >= MIN_AGREEMENT and ok_near),
    }


def _simulate(scene: str, n: int, seed: int) -> Any:
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from slipkit import config_dir
    from slipkit.sim.commands import build_scene

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={scene}"])
    GlobalHydra.instance().clear()
    return build_scene(cfg.scene).simulate(n, seed=seed)


def _stack(
    dataset: Any, stream: str, channels: list[str], label: str
) -> tuple[NDArray[np.float64], NDArray[np.int_], NDArray[np.int_]]:
    xs, ys, segs = [], [], []
    for k, tr in enumerate(dataset):
        df = tr.streams[stream]
        xs.append(df[channels].to_numpy(dtype=np.float64))
        if label == "slip_event":
            ys.append(tr.streams["truth_contact"]["slip_event"].to_numpy().astype(int))
        else:
            ys.append((df["t"].to_numpy() >= tr.labels[label]).astype(int))
        segs.append(np.full(len(df), k))
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(segs)


def _torsion(seed: int) -> tuple[NDArray[np.float64], NDArray[np.int_]]:
    # the recipe of tests/export/test_detector_export.py: drift + noise, a 10 Hz burst
    rng = np.random.default_rng(seed)
    t = np.arange(4000) / 1000.0
    x = 2.0 + 0.3 * t + rng.normal(0, 0.02, len(t))
    on = (t >= 2.0) & (t < 3.0)
    x[on] += 0.2 * np.sin(2 * np.pi * 10 * t[on])
    return x[:, None], on.astype(int)


def main() -> None:
    """Print parity and per-call time of every detector graph on simulated recordings.

    ``python -m slipkit.export.detectors``: thresholds fitted on 3 trials, parity
    (:func:`check_detector_parity`) on 3 other trials; time = median of 2000
    batch-1 onnxruntime calls (one thread) on held-out windows.
    """
    import time

    rows: list[tuple[str, StreamDetector, DetectorGraph, Any, Any]] = []
    for input_ in ("voltage", "force"):
        X, y, seg = _stack(
            _simulate("fsr_probe_slide", 3, 3), "fsr", ["voltage"], "slip_event"
        )
        Xh, _, sh = _stack(
            _simulate("fsr_probe_slide", 3, 4), "fsr", ["voltage"], "slip_event"
        )
        det: StreamDetector = FSRTouchSlip(input=input_).fit(X, y, segments=seg)
        rows.append(
            (f"FSRTouchSlip ({input_})", det, export_fsr_touch_slip(det), Xh, sh)
        )
    # the confirmed variant (configs/detector/fsr_robust.yaml: 3 peaks within 0.4 s), at
    # the paper's alpha and at the per-sample ROC's (near the noise: many close peaks)
    for thr in (8.0, None):
        det = FSRTouchSlip(confirm_events=3, confirm_window_s=0.4, threshold=thr)
        det.fit(X, y, segments=seg)
        rows.append(
            ("FSRTouchSlip (confirmed)", det, export_fsr_touch_slip(det), Xh, sh)
        )
    # mixed wirings (the hard scene): polarity per recording, the press_sign op before the
    # graph (parity runs it over every call of each held-out recording, as the loop does)
    import warnings

    from slipkit.baselines.fsr import PolarityWarning

    X, y, seg = _stack(
        _simulate("fsr_probe_slide_hard", 4, 3), "fsr", ["voltage"], "slip_event"
    )
    Xh, _, sh = _stack(
        _simulate("fsr_probe_slide_hard", 4, 4), "fsr", ["voltage"], "slip_event"
    )
    for name, kw in (
        ("FSR per-recording", {}),
        ("FSR per-rec. confirmed", {"confirm_events": 3, "confirm_window_s": 0.4}),
    ):
        det = FSRTouchSlip(threshold=8.0, **kw)  # type: ignore[arg-type]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PolarityWarning)
            det.fit(X, y, segments=seg)
        rows.append((name, det, export_fsr_touch_slip(det), Xh, sh))
    fit_ds, held = (
        _simulate("biotac_lift_slip", 3, 5),
        _simulate("biotac_lift_slip", 3, 6),
    )
    X, y, seg = _stack(fit_ds, "truth_force", ["fx", "fy"], "slip_onset_s")
    Xh, _, sh = _stack(held, "truth_force", ["fx", "fy"], "slip_onset_s")
    for thr in (0.5, None):
        det = ForceDerivative(threshold=thr).fit(X, y, segments=seg)
        rows.append(
            ("ForceDerivative (fx, fy)", det, export_force_derivative(det), Xh, sh)
        )
    X, y, seg = _stack(fit_ds, "pac", ["pac"], "slip_onset_s")
    Xh, _, sh = _stack(held, "pac", ["pac"], "slip_onset_s")
    base = pressure_baseline(PressureVibration(), X, segments=seg)
    for thr in (2.0, None):
        det = PressureVibration(baseline=base, threshold=thr).fit(X, y, segments=seg)
        rows.append(("PressureVibration", det, export_pressure_vibration(det), Xh, sh))
    Xt, yt = _torsion(0)
    det = TorsionalSlipDetector().fit(Xt, yt)
    rows.append(
        ("TorsionalSlipDetector", det, export_torsional_slip(det), _torsion(1)[0], None)
    )
    tail = float(rows[-2][2].features["tail"])  # type: ignore[index]
    swing = max(float(np.ptp(Xh[sh == k])) for k in np.unique(sh))
    print(
        f"pressure baseline (median over the fit trials): {base:.3f} counts; filter tail "
        f"T(L) = {tail:.2e}, largest held-out swing {swing:.0f} counts -> score error "
        f"bound T(L) x swing / baseline = {tail * swing / base:.1e}"
    )
    print(
        f"{'detector':26s} {'W':>4s} {'hop':>3s} {'threshold':>10s} {'calls':>6s} "
        f"{'agree %':>8s} {'flips':>5s} {'max|diff|':>9s} {'rel':>8s} {'eps':>8s} "
        f"{'gate eps':>8s} {'us/call':>7s}"
    )
    for name, det, graph, Xh, sh in rows:
        sess = onnx_session(graph)
        rep = check_detector_parity(det, graph, Xh, segments=sh, session=sess)
        windows, _ = detector_windows(graph, Xh if sh is None else Xh[sh == 0])
        feed = {graph.input_name: windows[:1]}
        times = []
        for j in range(2000):
            feed[graph.input_name] = windows[j % len(windows)][None]
            t0 = time.perf_counter_ns()
            sess.run([graph.score_output], feed)
            times.append(time.perf_counter_ns() - t0)
        print(
            f"{name:26s} {graph.window:4d} {graph.hop:3d} {det.threshold_:10.4g} "
            f"{rep['n_frames']:6d} {100 * rep['agreement']:8.3f} {rep['n_disagree']:5d} "
            f"{rep['max_abs_diff']:9.2e} {rep['max_rel_diff']:8.1e} {rep['score_eps']:8.1e} "
            + ("       -" if rep["gate_eps"] is None else f"{rep['gate_eps']:8.1e}")
            + f" {np.median(times) / 1e3:7.1f}"
            + ("" if rep["passed"] else "  PARITY FAILED")
        )


# ``python -m slipkit.export.detectors`` runs a second copy of this module as
# __main__ after the package import may already have registered the first one; only
# the imported module registers (a duplicate registration raises).
if __name__ != "__main__":
    register_exporter(FSRTouchSlip, export_fsr_touch_slip)
    register_exporter(ForceDerivative, export_force_derivative)
    register_exporter(PressureVibration, export_pressure_vibration)
    register_exporter(TorsionalSlipDetector, export_torsional_slip)

__all__ = [
    "DEFAULT_TAIL_TOL",
    "NO_SCORE",
    "DetectorGraph",
    "baseline_agreement",
    "check_detector_parity",
    "detector_windows",
    "export_force_derivative",
    "export_fsr_touch_slip",
    "export_pressure_vibration",
    "export_torsional_slip",
    "fsr_press_sign_step",
    "graph_scores",
    "pressure_baseline",
    "steady_state_fir",
    "with_fixed_baseline",
]

if __name__ == "__main__":
    main()
