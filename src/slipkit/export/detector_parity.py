"""Parity of an analytic detector's graph with the batch detector, on the windows the runtime
feeds and at the instants it would decide.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from sklearn.utils.validation import check_is_fitted

from slipkit._registry import Registry
from slipkit.baselines.base import StreamDetector, segment_bounds
from slipkit.export.detector_graph import NO_SCORE, DetectorGraph
from slipkit.export.parity import DEFAULT_EPS_REL, MIN_AGREEMENT, onnx_session
from slipkit.export.registry import (
    ExportError,
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


#: ``fn(detector, graph, x, instants) -> (margins, rest_gap)`` of a detector whose graph has a
#: touch gate (``graph.features["gate"]``): per instant, how far the batch detector's gate
#: input lies from the gate's threshold, and how far the graph's rest level is from the
#: recording's (a disagreement within that distance of the gate passes parity).
GateMargin = Callable[
    [Any, DetectorGraph, NDArray[np.float64], NDArray[np.int64]],
    tuple[NDArray[np.float64], float],
]

_GATE_MARGINS: Registry[type, GateMargin] = Registry(
    "gate margin", error=ExportError, n_args=4, key_type=type
)


def register_gate_margin(cls: type, fn: GateMargin, *, overwrite: bool = False) -> None:
    """Register the gate margin (:data:`GateMargin`) of a gated detector class's graphs,
    beside its exporter; subclasses inherit the entry."""
    _GATE_MARGINS.register(cls, fn, overwrite=overwrite)


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
        Graphs with a touch gate (a detector class with a registered
        :func:`register_gate_margin`, e.g. the FSR detector): a disagreement also
        passes when the batch detector's gate input (the FSR ``press``) lies within
        ``gate_eps`` of the gate's threshold, i.e. the gate flipped because the
        graph's rest differs from the recording's rest mean. Default: the largest
        such difference over the recordings, as the registered margin reports it.
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
    margin = _GATE_MARGINS.for_class(type(detector))
    gated = bool((graph.features or {}).get("gate")) and margin is not None
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
            assert margin is not None
            gm, gap = margin(detector, graph, Xv[a:z], inst)
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
