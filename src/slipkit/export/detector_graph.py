"""The window-in, score-out graph of an analytic detector and the pieces its exporters share.

See :mod:`slipkit.export.detectors` for the graph contract (window layout, ``NO_SCORE``,
NaN policy) and the family exporters built from these pieces.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import onnx
from numpy.typing import ArrayLike, NDArray
from onnx import helper
from scipy.signal import sosfilt, sosfilt_zi

from slipkit.baselines.base import StreamDetector
from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.parity import onnx_session
from slipkit.export.registry import (
    ExportedGraph,
    ExportError,
    producers,
)

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


def _band_matrix(g: GraphBuilder, v: str, m: NDArray[np.float64]) -> str:
    # The band-pass as one MatMul: ~W x n_out multiply-adds, one BLAS call in onnxruntime.
    return g.op("MatMul", v, g.const(m, np.float64), stem="band")


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
