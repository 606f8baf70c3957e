"""Export of :class:`~slipkit.models.frame_gru.FrameGRUDetector` as a one-frame step graph.

The graph takes one raw frame ``X`` (``batch x n_channels``) and the previous state
``h_in`` (``batch x hidden``) and returns the slip logit ``score`` (``batch``) and the
next state ``h_out``: the detector's standardisation folded into the input weights
(``W' = W / scale``, ``b' = b - W' mean``), one GRU step written as MatMul / Sigmoid /
Tanh ops in float64 (onnxruntime's CPU ``GRU`` kernel is float32 only, and float64
keeps the carried state equal to the numpy recurrence over a whole recording), and
the linear head. It is traced from a small torch module by ``torch.onnx.export``
(``dynamo=False``, as :mod:`slipkit.export.torch`).

The bundle's manifest carries the ``state`` section (``h_in`` -> ``h_out``, zeros at
the start), so :class:`~slipkit.runtime.loop.StreamLoop` feeds the state back frame
by frame and zeros it on a gap or a bad frame (``docs/deploy.md``, "Recurrent
state"). :func:`write_frame_gru_bundle` checks parity by running the graph through the
loop over held-out recordings frame by frame against the detector's batch scores
(:func:`check_step_parity`, on a temporary bundle), then writes the bundle.
"""

from __future__ import annotations

import io
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import onnx
from numpy.typing import NDArray
from sklearn.utils.validation import check_is_fitted

from slipkit.export.detectors import DetectorGraph
from slipkit.export.registry import (
    DEFAULT_OPSET,
    IR_VERSION,
    ExportError,
    check_opset,
    producers,
    register_exporter,
)
from slipkit.models.frame_gru import FrameGRUDetector

INPUT = "X"
STATE_IN = "h_in"
STATE_OUT = "h_out"
SCORE = "score"
#: Largest |loop score - batch score| accepted by :func:`check_step_parity`.
PARITY_TOL = 1e-5


@dataclass(frozen=True)
class StepGraph(DetectorGraph):
    """A :class:`DetectorGraph` of one frame with a recurrent state.

    Parameters
    ----------
    state : tuple of dict
        The manifest's ``state`` entries (``input``, ``output``, ``shape``, ``dtype``).
    """

    state: tuple[dict[str, Any], ...] = ()

    def describe(self) -> dict[str, Any]:
        """The detector graph's description plus its ``state`` entries."""
        out = super().describe()
        out["state"] = [dict(s) for s in self.state]
        return out


def _step_module(det: FrameGRUDetector) -> Any:
    import torch
    from torch import nn

    w_ih = det.w_ih_ / det.scale_  # standardisation folded into the input weights
    b_ih = det.b_ih_ - w_ih @ det.mean_
    n_h = int(det.hidden)

    def const(a: Any) -> torch.Tensor:
        return torch.tensor(np.asarray(a, dtype=np.float64))

    class Step(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.w_ih = nn.Parameter(const(w_ih.T), requires_grad=False)
            self.b_ih = nn.Parameter(const(b_ih), requires_grad=False)
            self.w_hh = nn.Parameter(const(det.w_hh_.T), requires_grad=False)
            self.b_hh = nn.Parameter(const(det.b_hh_), requires_grad=False)
            self.w_out = nn.Parameter(const(det.w_out_), requires_grad=False)
            self.b_out = nn.Parameter(const(det.b_out_), requires_grad=False)

        def forward(
            self, x: torch.Tensor, h: torch.Tensor
        ) -> tuple[torch.Tensor, torch.Tensor]:
            gi = x @ self.w_ih + self.b_ih
            gh = h @ self.w_hh + self.b_hh
            r = torch.sigmoid(gi[:, :n_h] + gh[:, :n_h])
            z = torch.sigmoid(gi[:, n_h : 2 * n_h] + gh[:, n_h : 2 * n_h])
            n = torch.tanh(gi[:, 2 * n_h :] + r * gh[:, 2 * n_h :])
            h_next = (1.0 - z) * n + z * h
            return h_next @ self.w_out + self.b_out, h_next

    return Step()


def export_frame_gru(
    detector: FrameGRUDetector, *, opset: int = DEFAULT_OPSET
) -> StepGraph:
    """Export a fitted :class:`FrameGRUDetector` as a float64 step graph (module doc)."""
    import torch

    check_is_fitted(detector, "threshold_")
    opset = check_opset(opset)
    c, n_h = int(detector.n_features_in_), int(detector.hidden)
    module = _step_module(detector)
    buffer = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        # the legacy exporter warns that it is deprecated (slipkit.export.torch)
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", FutureWarning)
        warnings.simplefilter("ignore", UserWarning)
        torch.onnx.export(
            module,
            (
                torch.zeros(1, c, dtype=torch.float64),
                torch.zeros(1, n_h, dtype=torch.float64),
            ),
            buffer,  # type: ignore[arg-type]  # the legacy exporter writes to file objects
            input_names=[INPUT, STATE_IN],
            output_names=[SCORE, STATE_OUT],
            dynamic_axes={
                INPUT: {0: "batch"},
                STATE_IN: {0: "batch"},
                SCORE: {0: "batch"},
                STATE_OUT: {0: "batch"},
            },
            opset_version=opset,
            dynamo=False,
        )
    model = onnx.load_from_string(buffer.getvalue())
    # finalize_model's contract is one input; this graph has the state besides.
    model.ir_version = IR_VERSION
    model.producer_name = "slipkit"
    try:
        onnx.checker.check_model(model, full_check=True)
    except onnx.checker.ValidationError as err:
        raise ExportError(f"the frame GRU step graph fails the checker: {err}") from err
    return StepGraph(
        model=model,
        input_name=INPUT,
        input_shape=("batch", c),
        output_names=tuple(o.name for o in model.graph.output),
        score_output=SCORE,
        score_meaning=(
            "FrameGRUDetector.decision_function: the slip logit after this frame's GRU "
            f"step; slip ('1') where score >= threshold ({float(detector.threshold_):.4g})"
        ),
        score_method="decision_function",
        opset=opset,
        classes=("0", "1"),
        threshold=float(detector.threshold_),
        network=True,
        input_meaning=f"one raw frame of {c} channel(s); the state h_in besides",
        features={"hidden": n_h, "channels": c},
        producers=producers(torch=torch.__version__),
        input_dtype="float64",
        window=1,
        hop=1,
        first_decision=0,
        state=(
            {
                "input": STATE_IN,
                "output": STATE_OUT,
                "shape": [1, n_h],
                "dtype": "float64",
            },
        ),
    )


register_exporter(FrameGRUDetector, export_frame_gru)


def step_manifest(
    graph: StepGraph,
    *,
    name: str,
    stream: str,
    channels: Sequence[str],
    rate_hz: float,
    p99_ms: float | None = None,
    debounce_k: int = 1,
    training: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """A bundle manifest (without ``files``) for a frame GRU step graph."""
    import onnxruntime

    period = 1000.0 / float(rate_hz)
    return {
        "name": name,
        "description": graph.score_meaning,
        "frame": {
            "streams": [stream],
            "channels": list(channels),
            "shape": [len(channels)],
            "window": 1,
            "hop": 1,
            "rate_hz": float(rate_hz),
        },
        "preprocessing": [],
        "inputs": [{"name": INPUT, "dtype": "float64", "shape": [1, len(channels)]}],
        "outputs": [{"name": SCORE}, {"name": STATE_OUT}],
        "decision": {
            "output": SCORE,
            "rule": "threshold",
            "column": 0,
            "classes": ["0", "1"],
            "positive": "1",
            "strict": False,
        },
        "threshold": graph.threshold,
        "state": [dict(s) for s in graph.state],
        "debounce": {"k": int(debounce_k)},
        "budget_ms": {
            "frame_period": period,
            "p99": period / 10.0 if p99_ms is None else float(p99_ms),
            "source": "data_rate_hz",
        },
        "session": {"intra_op_num_threads": 1, "inter_op_num_threads": 1},
        "opset": graph.opset,
        "producer": {**graph.producers, "onnxruntime": onnxruntime.__version__},
        "training": dict(training or {}),
    }


def check_step_parity(
    bundle_path: str | Path,
    detector: FrameGRUDetector,
    recordings: Sequence[NDArray[np.float64]],
    *,
    rate_hz: float,
    tol: float = PARITY_TOL,
) -> dict[str, Any]:
    """Run the bundle through :class:`StreamLoop` over the recordings as one stream,
    ten frame periods between one's last frame and the next's first (a gap: the loop
    zeros the state, as a new recording), and compare its scores with
    ``detector.decision_function`` of each recording, frame by frame.

    Returns
    -------
    dict
        ``recordings``, ``frames`` (pushed), ``max_abs_diff``, ``decisions_equal``,
        ``tol``, ``ok``, and in :func:`slipkit.export.commands`'s terms ``n_frames``
        (scored frames), ``agreement``, ``n_disagree``, ``score_eps`` (= ``tol``),
        ``disagreements_near_threshold`` and ``passed`` (= ``ok``).
    """
    from slipkit.export.parity import STREAM_GAP_PERIODS
    from slipkit.runtime import StreamLoop, load_bundle

    loop = StreamLoop(load_bundle(bundle_path), capacity=4096)
    xs = [np.asarray(rec, dtype=np.float64) for rec in recordings]
    t0 = 0.0
    for x in xs:
        for i, row in enumerate(x):
            loop.step(row, t0 + i / float(rate_hz))
        t0 += (len(x) - 1 + STREAM_GAP_PERIODS) / float(rate_hz)
    res = loop.result()
    worst, frames, same, scored_n, disagree = 0.0, 0, True, 0, 0
    for x in xs:
        want = detector.decision_function(x)
        mine = (res.frame >= frames) & (res.frame < frames + len(x))
        scored = np.isfinite(want)
        if not np.array_equal(res.frame[mine] - frames, np.flatnonzero(scored)):
            raise ExportError(
                "the loop scored other frames than the detector: "
                f"{int(mine.sum())} against {int(scored.sum())}"
            )
        diff = np.abs(res.score[mine] - want[scored])
        worst = max(worst, float(diff.max(initial=0.0)))
        # decisions may differ only where the score is within tol of the threshold
        close = np.abs(want[scored] - detector.threshold_) <= tol
        differ = res.slip[mine] != (want[scored] >= detector.threshold_)
        same &= bool(np.all(~differ | close))
        disagree += int(differ.sum())
        scored_n += int(scored.sum())
        frames += len(x)
    ok = worst <= tol and same
    return {
        "n_frames": scored_n,
        "agreement": 1.0 - disagree / max(scored_n, 1),
        "n_disagree": disagree,
        "score_eps": tol,
        "disagreements_near_threshold": same,
        "passed": ok,
        "recordings": len(recordings),
        "frames": frames,
        "max_abs_diff": worst,
        "decisions_equal": same,
        "tol": tol,
        "ok": ok,
    }


def graph_parity(
    detector: FrameGRUDetector,
    graph: StepGraph,
    recordings: Sequence[NDArray[np.float64]],
    *,
    rate_hz: float,
    tol: float = PARITY_TOL,
) -> dict[str, Any]:
    """:func:`check_step_parity` of ``graph`` in a temporary bundle (for ``slipkit export``)."""
    import tempfile

    from slipkit.runtime import write_bundle

    c = int(detector.n_features_in_)
    man = step_manifest(
        graph,
        name="parity",
        stream="parity",
        channels=[f"c{i}" for i in range(c)],
        rate_hz=rate_hz,
    )
    with tempfile.TemporaryDirectory(prefix="slipkit-gru-parity-") as tmp:
        path = write_bundle(Path(tmp) / "bundle", graph.serialize(), man)
        return check_step_parity(path, detector, recordings, rate_hz=rate_hz, tol=tol)


def write_frame_gru_bundle(
    detector: FrameGRUDetector,
    out: str | Path,
    held_out: Sequence[NDArray[np.float64]],
    *,
    name: str,
    stream: str,
    channels: Sequence[str],
    rate_hz: float,
    overwrite: bool = False,
    **manifest_options: Any,
) -> dict[str, Any]:
    """Export ``detector``, check parity on ``held_out`` recordings, write the bundle.

    Parity runs on a temporary bundle (:func:`graph_parity`, in the system's temp
    folder), so nothing is written beside ``out`` and no bundle is left at ``out``
    when parity fails.

    Returns
    -------
    dict
        The parity record (:func:`check_step_parity`) and ``path``.

    Raises
    ------
    ExportError
        Parity failed (the message gives the largest difference).
    """
    from slipkit.runtime import write_bundle

    graph = export_frame_gru(detector)
    parity = graph_parity(detector, graph, held_out, rate_hz=rate_hz)
    if not parity["ok"]:
        raise ExportError(
            f"frame GRU bundle parity failed: max |loop - batch| score "
            f"{parity['max_abs_diff']:.3g} (tol {parity['tol']:g}), decisions "
            f"equal: {parity['decisions_equal']}"
        )
    man = step_manifest(
        graph,
        name=name,
        stream=stream,
        channels=channels,
        rate_hz=rate_hz,
        **manifest_options,
    )
    man["training"] = {**man["training"], "parity": parity}
    target = Path(out)
    write_bundle(target, graph.serialize(), man, overwrite=overwrite)
    return {**parity, "path": str(target)}
