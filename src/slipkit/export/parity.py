"""Parity of an exported graph with its estimator, on held-out frames.

:func:`check_parity` compares the graph with the estimator window by window;
:func:`stream_parity` runs a bundle's loop over the held-out recordings as one
stream with gaps, as the gripper PC sees them, for bundles whose decisions depend on
earlier frames (stream state).

The graph runs in onnxruntime (CPU provider, one intra- and one inter-op
thread, as on the gripper PC) on the frames cast to the graph's input dtype
(float32, or float64 where :attr:`ExportedGraph.input_dtype` says so); the estimator runs
its own score method (``decision_function`` / ``predict_proba`` / ``predict``,
as :attr:`ExportedGraph.score_method` says) on the same frames as given. For a
graph with the TacTip pin-velocity features inside, the estimator gets
:func:`slipkit.features.pins.velocity_features` of the frames (float64 numpy).

The rule
--------
* Decisions (``classes[1]`` where a 1-D score exceeds the threshold, else the
  arg-max class) agree on at least 99.9 % of frames, and
* every disagreement lies within ``score_eps`` of the threshold, measured on the
  estimator's score (for per-class scores: half the gap between the two best
  classes, which is ``|p - 0.5|`` for two probabilities), and
* for networks (``graph.network``) and regressors, ``max |score difference| <=
  atol`` (1e-4).

Regressors have no decisions: their agreement is the fraction of frames whose
outputs all lie within ``atol``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slipkit.export.registry import ExportedGraph, ExportError

#: Minimum fraction of frames whose decisions agree.
MIN_AGREEMENT = 0.999
#: Default max |score difference| for networks and regressors.
DEFAULT_ATOL = 1e-4
#: Default score epsilon around the threshold, relative to the largest |score|
#: on the held-out frames (at least 1e-4 in absolute terms).
DEFAULT_EPS_REL = 1e-4


def onnx_session(graph: ExportedGraph, *, threads: int = 1) -> Any:
    """An onnxruntime session on the CPU provider with ``threads`` intra-op threads."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    return ort.InferenceSession(
        graph.serialize(), options, providers=["CPUExecutionProvider"]
    )


def run_graph(
    graph: ExportedGraph, X: ArrayLike, *, session: Any | None = None
) -> NDArray[np.float64]:
    """The graph's score output on ``X`` (cast to the graph's input dtype, float32 or
    float64, as the runtime feeds it), as float64."""
    sess = session if session is not None else onnx_session(graph)
    out = sess.run(
        [graph.score_output],
        {graph.input_name: np.asarray(X, dtype=np.dtype(graph.input_dtype))},
    )[0]
    return np.asarray(out, dtype=np.float64)


def estimator_inputs(graph: ExportedGraph, X: ArrayLike) -> NDArray[Any]:
    """What the estimator itself takes for the graph input ``X`` (features computed if in-graph)."""
    arr = np.asarray(X)
    spec = graph.features
    if spec is None:
        return arr
    if spec.get("kind") != "tactip_pin_velocity":
        raise ExportError(f"unknown in-graph feature kind {spec.get('kind')!r}")
    from slipkit.features.pins import velocity_features

    n = int(spec["n_pins"])
    p = np.asarray(arr, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (2, 2 * n):
        raise ExportError(f"pin frames must have shape (n, 2, {2 * n}); got {p.shape}")
    with np.errstate(invalid="ignore"):  # inf - inf marks a missing pin, as intended
        d = p[:, 1] - p[:, 0]
    dxy = np.stack([d[:, :n], d[:, n:]], axis=-1)
    return velocity_features(
        dxy,
        spec["variant"],
        shift_angles=bool(spec["shift_angles"]),
        missing_count=bool(spec["missing_count"]),
    )


def estimator_score(
    estimator: Any, graph: ExportedGraph, X: ArrayLike
) -> NDArray[np.float64]:
    """The estimator's own score for the graph input ``X`` (``graph.score_method``)."""
    Xe = estimator_inputs(graph, X)
    method = graph.score_method
    if method == "forward":
        import torch

        with torch.no_grad():
            out = estimator(torch.as_tensor(np.asarray(Xe, dtype=np.float32)))
        return np.asarray(out.detach().numpy(), dtype=np.float64)
    return np.asarray(getattr(estimator, method)(Xe), dtype=np.float64)


def _decisions(
    score: NDArray[np.float64], threshold: float | None
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Decision index per frame and its distance to the decision boundary."""
    if score.ndim == 1:
        thr = 0.0 if threshold is None else threshold
        return (score > thr).astype(np.int64), np.abs(score - thr)
    if score.shape[1] == 1:
        return _decisions(score[:, 0], threshold)
    top2 = np.sort(score, axis=1)[:, -2:]
    return np.argmax(score, axis=1), (top2[:, 1] - top2[:, 0]) / 2.0


def check_parity(
    estimator: Any,
    graph: ExportedGraph,
    X_held_out: ArrayLike,
    *,
    score_eps: float | None = None,
    atol: float = DEFAULT_ATOL,
    session: Any | None = None,
) -> dict[str, Any]:
    """Compare the graph in onnxruntime with the estimator on held-out frames.

    Parameters
    ----------
    estimator : object
        The fitted estimator (or torch module for ``score_method == "forward"``).
    graph : ExportedGraph
        Its export.
    X_held_out : array_like
        Frames in the graph's input layout (features, or raw pin frames for a graph
        with the features inside), not used in training.
    score_eps : float, optional
        Disagreements must lie within this distance of the threshold (score
        units). Default: 1e-4 times the largest |score| of the estimator on these
        frames, at least 1e-4.
    atol : float
        Max |score difference| allowed for networks and regressors.
    session : onnxruntime.InferenceSession, optional
        Reuse a session (else one is made: CPU, one thread).

    Returns
    -------
    dict
        ``n_frames``, ``agreement`` (fraction of frames whose decisions agree),
        ``n_disagree``, ``max_abs_diff``, ``max_rel_diff`` (max |diff| over the
        largest |score|), ``score_eps``, ``atol``, ``disagreements_near_threshold``
        (bool), ``has_decisions`` and ``passed`` (the rule in the module notes).
    """
    X = np.asarray(X_held_out)
    if len(X) == 0:
        raise ExportError("parity needs at least one held-out frame; got none")
    ours = run_graph(graph, X, session=session)
    ref = estimator_score(estimator, graph, X)
    if ours.size != ref.size:
        raise ExportError(
            f"graph output {graph.score_output!r} has shape {ours.shape}; "
            f"estimator {graph.score_method} gave {ref.shape}"
        )
    ours = ours.reshape(ref.shape)
    diff = np.abs(ours - ref)
    scale = float(np.max(np.abs(ref))) if ref.size else 0.0
    eps = (
        max(DEFAULT_EPS_REL * scale, DEFAULT_EPS_REL)
        if score_eps is None
        else float(score_eps)
    )
    has_decisions = graph.classes is not None and graph.score_method in (
        "decision_function",
        "predict_proba",
        "forward",
    )
    if has_decisions:
        d_ref, margin = _decisions(ref, graph.threshold)
        d_ours, _ = _decisions(ours, graph.threshold)
        disagree = d_ref != d_ours
        near = bool(np.all(margin[disagree] <= eps))
    else:
        rows = diff.reshape(len(X), -1)
        disagree = ~np.all(rows <= atol, axis=1)
        near = True
    agreement = 1.0 - float(np.mean(disagree))
    max_abs = float(diff.max())
    exact_needed = graph.network or not has_decisions
    passed = (
        agreement >= MIN_AGREEMENT and near and (not exact_needed or max_abs <= atol)
    )
    return {
        "n_frames": len(X),
        "agreement": agreement,
        "n_disagree": int(np.sum(disagree)),
        "max_abs_diff": max_abs,
        "max_rel_diff": max_abs / scale if scale > 0 else max_abs,
        "score_eps": eps,
        "atol": atol,
        "disagreements_near_threshold": near,
        "has_decisions": has_decisions,
        "passed": bool(passed),
    }


#: Frame periods between two held-out recordings in the stream of :func:`stream_parity`:
#: more than the loop's ``max_gap_periods`` (1.5), so each boundary is a gap.
STREAM_GAP_PERIODS = 10.0


def stream_parity(
    bundle_path: Any,
    recordings: Sequence[ArrayLike],
    reference: Callable[[int, NDArray[np.intp]], ArrayLike],
    *,
    score_eps: float | None = None,
    atol: float | None = None,
    gap_periods: float = STREAM_GAP_PERIODS,
) -> dict[str, Any]:
    """A bundle through :class:`~slipkit.runtime.StreamLoop` over held-out recordings
    joined into one stream, as the runtime sees them, against the model per recording.

    The recordings follow each other with ``gap_periods`` frame periods between one's
    last frame and the next's first (timestamps at the bundle's rate), so a bundle
    with stream state starts each from scratch (``docs/deploy.md``, *Stream
    state*). Each decision is mapped to its recording and frame there; the loop must
    decide on exactly each recording's own grid (``window - 1 + j hop``, less the
    windows it skips for a non-finite frame or input), and its decisions must agree
    with the reference's as :func:`check_parity`'s rule says (>= 99.9 % of calls,
    every disagreement within ``score_eps`` of the threshold; ``atol`` on the
    scores when given).

    Parameters
    ----------
    bundle_path : path
        The bundle folder (a temporary one during ``slipkit export``).
    recordings : sequence of array_like (n, *frame.shape)
        The held-out recordings, raw frames.
    reference : callable
        ``reference(k, ends)``: the model's own score output for recording ``k`` at
        its (0-based) frames ``ends``, one row per frame, as the manifest's decision
        reads it.
    score_eps : float, optional
        Default: 1e-4 x the largest finite |reference score|, at least 1e-4.
    atol : float, optional
        Max |loop score - reference score| (networks and regressors); None: not checked.

    Returns
    -------
    dict
        ``recordings``, ``frames`` (pushed), ``gaps``, ``n_frames`` (decisions
        compared), ``calls_match`` (the loop decided on each recording's grid),
        ``agreement``, ``n_disagree``, ``max_abs_diff``, ``score_eps``, ``atol``,
        ``disagreements_near_threshold`` and ``passed``.
    """
    from slipkit.export.deploy import loop_ends, slip_decisions
    from slipkit.runtime import StreamLoop, load_bundle
    from slipkit.runtime.sources import Frame

    bundle = load_bundle(bundle_path)
    m = bundle.manifest
    frame = {
        "window": m.frame.window,
        "hop": m.frame.hop,
        "streams": list(m.frame.streams),
    }
    xs = [
        np.asarray(r, dtype=np.float64).reshape(-1, *m.frame.shape) for r in recordings
    ]
    starts = np.cumsum([0] + [len(x) for x in xs])
    period = 1.0 / m.frame.rate_hz

    def stream() -> Any:
        t0, clock = 0.0, time.perf_counter_ns
        for x in xs:
            for i, row in enumerate(x):
                yield Frame(i, t0 + i * period, row, clock())
            t0 += (len(x) - 1 + gap_periods) * period

    loop = StreamLoop(bundle, capacity=max(int(starts[-1]) // m.frame.hop + 1, 16))
    res = loop.run(stream())
    rec = np.searchsorted(starts, res.frame, side="right") - 1
    local = res.frame - starts[rec]
    d = m.decision
    decision = dict(m.raw["decision"])
    loop_slip, loop_score = res.slip, res.score
    ref_slip, ref_score, margin = [], [], []
    calls_match = True
    missing = 0
    order = []
    for k, x in enumerate(xs):
        mine = np.flatnonzero(rec == k)
        want = loop_ends(x, frame, skip_nonfinite=True)
        ends = local[mine].astype(np.intp)
        if not np.all(np.isin(ends, want)):
            calls_match = False
        missing += len(want) - int(np.isin(want, ends).sum())
        if not len(ends):
            continue
        raw = np.asarray(reference(k, ends), dtype=np.float64).reshape(len(ends), -1)
        ref_slip.append(slip_decisions(raw, decision, d.threshold))
        if d.rule == "argmax":
            ref_score.append(raw[:, list(d.slip_columns)].max(axis=1))
            top2 = np.sort(raw, axis=1)[:, -2:]
            margin.append((top2[:, 1] - top2[:, 0]) / 2.0)
        else:
            col = raw[:, d.column]
            ref_score.append(col)
            thr = 0.0 if d.threshold is None else d.threshold
            with np.errstate(invalid="ignore"):
                margin.append(np.where(np.isnan(col), np.inf, np.abs(col - thr)))
        order.append(mine)
    if missing != res.nonfinite_windows:
        calls_match = False
    if not order:
        raise ExportError("stream parity: the loop made no decision on the recordings")
    idx = np.concatenate(order)
    want_slip, want_score = np.concatenate(ref_slip), np.concatenate(ref_score)
    gap = np.concatenate(margin)
    disagree = want_slip != loop_slip[idx]
    finite = np.isfinite(want_score) & np.isfinite(loop_score[idx])
    diff = np.abs(want_score[finite] - loop_score[idx][finite])
    scale = float(np.max(np.abs(want_score[finite]))) if finite.any() else 0.0
    eps = (
        max(DEFAULT_EPS_REL * scale, DEFAULT_EPS_REL)
        if score_eps is None
        else float(score_eps)
    )
    near = bool(np.all(gap[disagree] <= eps))
    agreement = 1.0 - float(np.mean(disagree))
    max_abs = float(diff.max()) if diff.size else 0.0
    passed = (
        calls_match
        and agreement >= MIN_AGREEMENT
        and near
        and (atol is None or max_abs <= atol)
    )
    return {
        "recordings": len(xs),
        "frames": int(starts[-1]),
        "gaps": res.gaps,
        "n_frames": len(idx),
        "calls_match": calls_match,
        "agreement": agreement,
        "n_disagree": int(disagree.sum()),
        "max_abs_diff": max_abs,
        "score_eps": eps,
        "atol": atol,
        "disagreements_near_threshold": near,
        "passed": bool(passed),
    }
