"""onnxruntime session options as a manifest records them, and sessions built from them.

The options that matter for one-frame-at-a-time inference on a small CPU: intra-op
threads (a second thread costs a hand-off per node; it pays only for big MatMuls),
the graph optimisation level, and spinning (a spinning worker answers faster but
burns its core, which a gripper PC may need for the camera). ``warmup`` calls run
before the first frame so allocation and kernel selection never land in a decision.
:mod:`slipkit.runtime.tuning` measures these options on a bundle's own frames.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import onnxruntime as ort

from slipkit.runtime._schema import Fields

#: manifest name -> onnxruntime level.
GRAPH_OPT_LEVELS: dict[str, ort.GraphOptimizationLevel] = {
    "disabled": ort.GraphOptimizationLevel.ORT_DISABLE_ALL,
    "basic": ort.GraphOptimizationLevel.ORT_ENABLE_BASIC,
    "extended": ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED,
    "all": ort.GraphOptimizationLevel.ORT_ENABLE_ALL,
}

SESSION_FIELDS = (
    "intra_op_num_threads",
    "inter_op_num_threads",
    "graph_optimization_level",
    "allow_spinning",
    "warmup",
)


@dataclass(frozen=True)
class SessionSpec:
    """How to build the inference session (the manifest's ``session`` object).

    Parameters
    ----------
    intra_op_num_threads : int
        Threads inside one operator (1 = the calling thread only).
    inter_op_num_threads : int
        Threads across independent operators (sequential execution uses 1).
    graph_optimization_level : {"disabled", "basic", "extended", "all"}
        onnxruntime graph rewrites applied when the session is created.
    allow_spinning : bool
        Let idle intra-op workers spin instead of sleeping (only matters with
        more than one intra-op thread).
    warmup : int
        Calls on a zero input before the first frame.
    """

    intra_op_num_threads: int = 1
    inter_op_num_threads: int = 1
    graph_optimization_level: str = "all"
    allow_spinning: bool = False
    warmup: int = 20

    @classmethod
    def from_fields(cls, f: Fields) -> SessionSpec:
        """Read and check the manifest's ``session`` object (absent fields default)."""
        f.only(SESSION_FIELDS)
        d = cls()
        return cls(
            intra_op_num_threads=f.integer(
                "intra_op_num_threads", d.intra_op_num_threads, minimum=1
            ),
            inter_op_num_threads=f.integer(
                "inter_op_num_threads", d.inter_op_num_threads, minimum=1
            ),
            graph_optimization_level=f.string(
                "graph_optimization_level",
                d.graph_optimization_level,
                choices=list(GRAPH_OPT_LEVELS),
            ),
            allow_spinning=f.boolean("allow_spinning", d.allow_spinning),
            warmup=f.integer("warmup", d.warmup, minimum=0),
        )

    def to_json(self) -> dict[str, Any]:
        """The manifest's ``session`` object."""
        return asdict(self)

    def options(self) -> ort.SessionOptions:
        """The equivalent :class:`onnxruntime.SessionOptions`."""
        so = ort.SessionOptions()
        so.intra_op_num_threads = self.intra_op_num_threads
        so.inter_op_num_threads = self.inter_op_num_threads
        so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        so.graph_optimization_level = GRAPH_OPT_LEVELS[self.graph_optimization_level]
        spin = "1" if self.allow_spinning else "0"
        so.add_session_config_entry("session.intra_op.allow_spinning", spin)
        so.add_session_config_entry("session.inter_op.allow_spinning", spin)
        return so


def make_session(model: bytes, spec: SessionSpec) -> ort.InferenceSession:
    """An onnxruntime session on the CPU provider from ONNX bytes and options."""
    return ort.InferenceSession(
        model, sess_options=spec.options(), providers=["CPUExecutionProvider"]
    )
