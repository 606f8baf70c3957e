"""ONNX for the window-statistics pipelines and the candidate search.

* :class:`~slipkit.models.window_features.WindowStatistics` gets a skl2onnx shape
  calculator and converter (``update_registered_converter``, skl2onnx's documented
  way for custom transformers), so a ``Pipeline(WindowStatistics, StandardScaler,
  LogisticRegression | SVC | MLPClassifier)`` converts whole through
  :func:`slipkit.export.sklearn.export_sklearn`. The graph: Reshape ``(N, W*C) ->
  (N, W, C)``, optional Sub of the first frame, ReduceMean / ReduceMin / ReduceMax
  over the frames, ``sqrt(mean((x - mean)^2))``, last minus first frame (Slice),
  ``mean(|x[1:] - x[:-1]|)``, Concat in the transformer's order.
* :class:`~slipkit.models.selection.CandidateSearch` exports its chosen, refitted
  estimator (``best_estimator_``) with that estimator's exporter.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from slipkit.export.registry import ExportedGraph, export, register_exporter
from slipkit.models.selection import CandidateSearch
from slipkit.models.window_features import WindowStatistics

__all__ = ["export_candidate_search"]


def _shape(operator: Any) -> None:
    from skl2onnx.common.data_types import FloatTensorType

    op = operator.raw_operator
    n = operator.inputs[0].get_first_dimension()
    operator.outputs[0].type = FloatTensorType([n, len(op.stats) * op.n_channels])


def _convert(scope: Any, operator: Any, container: Any) -> None:
    from onnx import TensorProto

    op: WindowStatistics = operator.raw_operator
    opset = container.target_opset
    x_in = operator.inputs[0].full_name
    out = operator.outputs[0].full_name
    w, c = int(op.width_), int(op.n_channels)

    def name(stem: str) -> str:
        return scope.get_unique_variable_name(stem)

    def const(stem: str, value: Any, dtype: Any = np.int64) -> str:
        n = name(stem)
        arr = np.asarray(value, dtype=dtype)
        container.add_initializer(
            n,
            TensorProto.INT64 if dtype == np.int64 else TensorProto.FLOAT,
            list(arr.shape),
            arr.ravel().tolist(),
        )
        return n

    def node(kind: str, inputs: list[str], stem: str, **attrs: Any) -> str:
        n = name(stem)
        container.add_node(
            kind, inputs, [n], name=scope.get_unique_operator_name(kind), **attrs
        )
        return n

    def reduce(kind: str, x: str, stem: str) -> str:
        # axes became an input of ReduceMean / Min / Max at opset 18.
        if opset >= 18:
            return node(kind, [x, const("axes", [1])], stem, keepdims=0)
        return node(kind, [x], stem, axes=[1], keepdims=0)

    def frames(x: str, start: int, end: int, stem: str) -> str:
        return node(
            "Slice", [x, const("s", [start]), const("e", [end]), const("a", [1])], stem
        )

    v = node("Reshape", [x_in, const("shape", [-1, w, c])], "frames")
    first = frames(v, 0, 1, "first")
    if op.subtract_first:
        v = node("Sub", [v, first], "rel")
        first = frames(v, 0, 1, "first_rel")
    parts: dict[str, str] = {}
    mean3 = None
    for s in op.stats:
        if s == "mean":
            parts[s] = reduce("ReduceMean", v, "mean")
        elif s == "std":
            if mean3 is None:
                mean3 = node(
                    "Unsqueeze",
                    [reduce("ReduceMean", v, "m"), const("ax", [1])],
                    "mean3",
                )
            dev = node("Sub", [v, mean3], "dev")
            var = reduce("ReduceMean", node("Mul", [dev, dev], "sq"), "var")
            parts[s] = node("Sqrt", [var], "std")
        elif s == "min":
            parts[s] = reduce("ReduceMin", v, "min")
        elif s == "max":
            parts[s] = reduce("ReduceMax", v, "max")
        elif s == "last_first":
            last = frames(v, w - 1, w, "last")
            diff = node("Sub", [last, first], "lf3")
            parts[s] = node("Reshape", [diff, const("s2", [-1, c])], "last_first")
        elif s == "mean_abs_diff":
            if w > 1:
                step = node(
                    "Sub", [frames(v, 1, w, "next"), frames(v, 0, w - 1, "prev")], "d"
                )
                parts[s] = reduce("ReduceMean", node("Abs", [step], "ad"), "mad")
            else:  # one frame: no change seen (as in the transformer)
                zero = const("zero", [0.0], np.float32)
                f2 = node("Reshape", [first, const("s2", [-1, c])], "f2")
                parts[s] = node("Mul", [f2, zero], "mad")
    container.add_node(
        "Concat",
        [parts[s] for s in op.stats],
        [out],
        name=scope.get_unique_operator_name("Concat"),
        axis=1,
    )


def _register_skl2onnx() -> None:
    try:
        from skl2onnx import update_registered_converter
    except ImportError:  # the train extra is not installed: nothing to convert
        return
    update_registered_converter(
        WindowStatistics, "SlipkitWindowStatistics", _shape, _convert
    )


def export_candidate_search(
    estimator: CandidateSearch, **options: Any
) -> ExportedGraph:
    """The chosen estimator's graph (its own exporter; options passed through)."""
    return export(estimator.best_estimator_, **options)


_register_skl2onnx()
register_exporter(CandidateSearch, export_candidate_search)
