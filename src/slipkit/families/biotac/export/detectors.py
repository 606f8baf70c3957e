"""Exporters of the BioTac force-derivative and pressure-vibration detectors (a windowed FIR
stand-in for the IIR band-pass, over a fixed baseline).

The graph contract: :mod:`slipkit.export.detectors`.

* :class:`~slipkit.families.biotac.detectors.ForceDerivative` -- ``W = span + 1`` (4):
  ``Ft = sqrt(fx^2 + fy^2)`` (or ``Ft`` itself) at both ends, ``-(Ft[-1] - Ft[0])
  rate / span``; the same numbers as the batch detector.
* :class:`~slipkit.families.biotac.detectors.PressureVibration` -- the IIR band-pass as one
  MatMul over ``W = L + window - 1`` samples (:func:`~slipkit.export.detector_graph.steady_state_fir`), rectify,
  ``TopK`` for the ``n_exceed``-th largest of the last ``window`` outputs, over a
  **fixed baseline** (the detector's ``baseline`` option).

Parity and time per call on simulated lifts: ``python -m slipkit.families.biotac.export.parity``.
"""

from __future__ import annotations

import copy
import math

import numpy as np
from numpy.typing import ArrayLike
from onnx import helper
from scipy.signal import sosfilt, sosfilt_zi
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import segment_bounds
from slipkit.export._graph import GraphBuilder
from slipkit.export.detector_graph import (
    DEFAULT_TAIL_TOL,
    NO_SCORE,
    DetectorGraph,
    _axes,
    _band_matrix,
    _finish,
    _graph,
    _not_finite,
    _prologue,
    steady_state_fir,
)
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportError,
    RuntimeSteps,
    StreamContext,
    register_exporter,
    register_runtime_steps,
)
from slipkit.families.biotac.detectors import ForceDerivative, PressureVibration


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
            "baseline=<counts> (e.g. slipkit.families.biotac.export.detectors.pressure_baseline("
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


def pressure_runtime_steps(det: PressureVibration, ctx: StreamContext) -> RuntimeSteps:
    """A detector that measures its baseline per recording deploys with a fixed one.

    The graph needs a fixed baseline: the median over the training recordings. The
    graph then computes the detector with that baseline, so parity checks it against
    that detector (against the per-recording one the scores differ by the ratio of the
    baselines, not by rounding), and the note states how often it decides as the
    trained detector on the held-out trials.
    """
    if det.baseline is not None:
        return RuntimeSteps()
    rec = ctx.frames(ctx.train_ids)
    X = np.concatenate([r.frames for r in rec])
    seg = np.concatenate([np.full(len(r.frames), k) for k, r in enumerate(rec)])
    base = pressure_baseline(det, X, segments=seg)
    deployed = with_fixed_baseline(det, base)
    agree, n = baseline_agreement(
        det,
        deployed,
        np.concatenate([r.frames for r in ctx.held]),
        segments=np.concatenate(
            [np.full(len(r.frames), k) for k, r in enumerate(ctx.held)]
        ),
    )
    return RuntimeSteps(
        notes=[
            f"fixed pressure baseline {base:.4g} counts RMS (median of the training "
            "recordings; the trained detector measures one per recording): the bundle "
            f"deploys PressureVibration(baseline={base:.4g}), which decides as the "
            f"trained detector on {100 * agree:.2f} % of {n} held-out samples"
        ],
        model=deployed,
    )


register_exporter(ForceDerivative, export_force_derivative)
register_exporter(PressureVibration, export_pressure_vibration)
register_runtime_steps(PressureVibration, pressure_runtime_steps)
