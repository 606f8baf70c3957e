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
from onnxruntime.capi import onnxruntime_pybind11_state as _ort_state

from slipkit.runtime._schema import MAX_THREADS, MAX_WARMUP, Fields

#: The exception types onnxruntime raises (each derives from ``Exception`` directly,
#: so they are listed by name; RuntimeError covers the pybind layer's own). The
#: runtime turns them into :class:`~slipkit.runtime.errors.BundleError` naming
#: ``model.onnx``.
ORT_ERRORS: tuple[type[BaseException], ...] = (
    RuntimeError,
    *(
        cls
        for cls in vars(_ort_state).values()
        if isinstance(cls, type)
        and issubclass(cls, Exception)
        and cls.__module__ == _ort_state.__name__
    ),
)

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
        Threads inside one operator (1 = the calling thread only; at most
        :data:`~slipkit.runtime._schema.MAX_THREADS`).
    inter_op_num_threads : int
        Threads across independent operators (sequential execution uses 1; at
        most ``MAX_THREADS``).
    graph_optimization_level : {"disabled", "basic", "extended", "all"}
        onnxruntime graph rewrites applied when the session is created.
    allow_spinning : bool
        Let idle intra-op workers spin instead of sleeping (only matters with
        more than one intra-op thread).
    warmup : int
        Calls on a zero input before the first frame (at most
        :data:`~slipkit.runtime._schema.MAX_WARMUP`; the warm-up also stops once it
        has taken the bundle's load deadline, :func:`slipkit.runtime.load_bundle`).
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
                "intra_op_num_threads",
                d.intra_op_num_threads,
                minimum=1,
                maximum=MAX_THREADS,
            ),
            inter_op_num_threads=f.integer(
                "inter_op_num_threads",
                d.inter_op_num_threads,
                minimum=1,
                maximum=MAX_THREADS,
            ),
            graph_optimization_level=f.string(
                "graph_optimization_level",
                d.graph_optimization_level,
                choices=list(GRAPH_OPT_LEVELS),
            ),
            allow_spinning=f.boolean("allow_spinning", d.allow_spinning),
            warmup=f.integer("warmup", d.warmup, minimum=0, maximum=MAX_WARMUP),
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
        # Fatal only: onnxruntime would also print its errors (in colour) on stderr,
        # but each one is raised as well, and the runtime reports it as one line.
        so.log_severity_level = 4
        spin = "1" if self.allow_spinning else "0"
        so.add_session_config_entry("session.intra_op.allow_spinning", spin)
        so.add_session_config_entry("session.inter_op.allow_spinning", spin)
        return so


def make_session(model: bytes, spec: SessionSpec) -> ort.InferenceSession:
    """An onnxruntime session on the CPU provider from ONNX bytes and options."""
    return ort.InferenceSession(
        model, sess_options=spec.options(), providers=["CPUExecutionProvider"]
    )
