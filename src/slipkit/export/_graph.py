"""A small helper to write ONNX graphs node by node (constants, unique names)."""

from __future__ import annotations

from typing import Any

import numpy as np
import onnx
from numpy.typing import ArrayLike
from onnx import TensorProto, helper, numpy_helper

from slipkit.export.registry import check_opset, finalize_model

FLOAT = TensorProto.FLOAT
DOUBLE = TensorProto.DOUBLE


class GraphBuilder:
    """Collects nodes and constant initializers; :meth:`build` makes the checked model.

    Parameters
    ----------
    name : str
        Graph name.
    opset : int
        Default-domain opset (17 or 18).
    """

    def __init__(self, name: str, opset: int) -> None:
        self.name = name
        self.opset = check_opset(opset)
        self.nodes: list[onnx.NodeProto] = []
        self.initializers: list[onnx.TensorProto] = []
        self._count = 0

    def _fresh(self, stem: str) -> str:
        self._count += 1
        return f"{stem}_{self._count}"

    def const(self, value: ArrayLike, dtype: Any = np.float32, stem: str = "c") -> str:
        """A constant initializer of ``value`` cast to ``dtype``; returns its name."""
        name = self._fresh(stem)
        self.initializers.append(
            numpy_helper.from_array(np.asarray(value, dtype=dtype), name)
        )
        return name

    def op(self, op_type: str, *inputs: str, stem: str = "", **attrs: Any) -> str:
        """Append one node with a single output; returns the output name."""
        out = self._fresh(stem or op_type.lower())
        self.nodes.append(helper.make_node(op_type, list(inputs), [out], **attrs))
        return out

    def rename(self, value: str, name: str) -> str:
        """Expose ``value`` under ``name`` (an Identity node), e.g. as a graph output."""
        self.nodes.append(helper.make_node("Identity", [value], [name]))
        return name

    def build(
        self,
        inputs: list[onnx.ValueInfoProto],
        outputs: list[onnx.ValueInfoProto],
        doc: str = "",
        extra_inputs: tuple[str, ...] = (),
    ) -> onnx.ModelProto:
        """The model, stamped and checked by :func:`finalize_model` (``extra_inputs``:
        inputs besides the frame input, as there)."""
        graph = helper.make_graph(
            self.nodes, self.name, inputs, outputs, self.initializers, doc_string=doc
        )
        model = helper.make_model(
            graph, opset_imports=[helper.make_opsetid("", self.opset)]
        )
        return finalize_model(model, extra_inputs)
