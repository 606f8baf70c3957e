"""The analytic detectors' graph contract: a window in, the score out.

The code lives in one module per piece: :mod:`~slipkit.export.detector_graph` (the graph type
and shared pieces) and :mod:`~slipkit.export.detector_parity`; this module re-exports their
names and holds the parity benchmark's helpers (:func:`print_parity_rows`). Family folders
export their detectors with these pieces (``slipkit/families/<family>/export/``, e.g. the
BioTac force-derivative and pressure-vibration graphs, the FSR touch-and-slip graph) and
print their parity with ``python -m slipkit.families.<family>.export.parity``.

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
each family's ``python -m slipkit.families.<family>.export.parity`` prints it (and the
time per call) for its detectors on simulated recordings.

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

from typing import Any

import numpy as np
from numpy.typing import NDArray

from slipkit.baselines.base import StreamDetector
from slipkit.export.detector_graph import (  # noqa: F401
    _F32_MAX,
    _MAX_TAPS,
    DEFAULT_TAIL_TOL,
    NO_SCORE,
    SCORE,
    WINDOW_INPUT,
    DetectorGraph,
    _axes,
    _band_matrix,
    _finish,
    _graph,
    _not_finite,
    _prologue,
    steady_state_fir,
)
from slipkit.export.detector_parity import (  # noqa: F401
    _preprocessed_windows,
    check_detector_parity,
    detector_windows,
    graph_scores,
)
from slipkit.export.parity import onnx_session


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


def print_parity_rows(
    rows: list[tuple[str, StreamDetector, DetectorGraph, Any, Any]],
) -> None:
    """Print parity and per-call time of ``(name, detector, graph, X held out, segments)``
    rows: :func:`check_detector_parity`, then the median of 2000 batch-1 onnxruntime calls
    on held-out windows."""
    import time

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


__all__ = [
    "DEFAULT_TAIL_TOL",
    "NO_SCORE",
    "DetectorGraph",
    "check_detector_parity",
    "detector_windows",
    "graph_scores",
    "print_parity_rows",
    "steady_state_fir",
]
