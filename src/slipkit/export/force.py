"""Exporters of the analytic BioTac force models: hand-built graphs, evaluated in float64.

* :class:`~slipkit.models.force.WeightedNormalsRegressor` -- ``F_k = S_k sum_i E_i
  N_k,i + o_k`` is one matrix product: ``Gemm(x, W, o)`` with ``W[i, k] = N_k,i S_k``
  for the electrode columns and zero rows for any extra input column (the model reads
  only its electrodes).
* :class:`~slipkit.models.force.LocalLinearRegressor` -- with ``z = (x - mean) /
  scale``, the receptive-field activations are ``softmax(-||z - c_k||^2 / 2 h^2)``
  (``||z||^2 - 2 z C^T + ||C||^2`` by one ``Gemm``), every local ridge model ``W_k (z
  - c_k) + b_k`` is one column block of ``z @ [W_1^T .. W_K^T] + [b_k - W_k c_k]``,
  and the prediction is the activation-weighted sum over fields (``Mul`` +
  ``ReduceSum``).

Both graphs cast their float32 input to float64 first and their output back to
float32 at the end: the electrode inputs are counts of order 10^2-10^3 and the
LWR distances cancel, so float32 arithmetic inside would cost more than the input
cast does. The output is ``predict`` (N), shape ``(batch, n_outputs)`` (``(batch,)``
for a model fitted on a 1-D target).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from onnx import helper
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    ExportError,
    producers,
    register_exporter,
)
from slipkit.models.force import LocalLinearRegressor, WeightedNormalsRegressor

INPUT = "features"
SCORE = "score"


def _finish(
    g: GraphBuilder,
    out64: str,
    *,
    n_features: int,
    n_outputs: int,
    one_d: bool,
    name: str,
    doc: str,
) -> ExportedGraph:
    """Cast to float32, flatten a 1-D model's output, build, wrap as an ExportedGraph."""
    out = g.op("Cast", out64, to=FLOAT)
    if one_d:
        g.nodes.append(
            helper.make_node("Reshape", [out, g.const([-1], np.int64)], [SCORE])
        )
        out_shape: list[str | int] = ["batch"]
    else:
        g.rename(out, SCORE)
        out_shape = ["batch", n_outputs]
    model = g.build(
        [helper.make_tensor_value_info(INPUT, FLOAT, ["batch", n_features])],
        [helper.make_tensor_value_info(SCORE, FLOAT, out_shape)],
        doc=doc,
    )
    import sklearn

    return ExportedGraph(
        model=model,
        input_name=INPUT,
        input_shape=("batch", n_features),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning=f"{name}.predict: force (N), {n_outputs} output(s)",
        score_method="predict",
        opset=g.opset,
        input_meaning=f"{n_features} electrode values (counts), as the model was fitted",
        producers=producers(**{"scikit-learn": sklearn.__version__}),
    )


def export_weighted_normals(
    estimator: WeightedNormalsRegressor, *, opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Export a fitted :class:`WeightedNormalsRegressor` as one float64 ``Gemm``.

    Parameters
    ----------
    estimator : WeightedNormalsRegressor
        Fitted.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Input ``"features"`` ``(batch, n_features_in_)`` float32 (counts), output
        ``"score"``: ``predict`` (N).
    """
    check_is_fitted(estimator)
    normals = np.asarray(estimator.normals_, dtype=np.float64)
    n_features = int(estimator.n_features_in_)
    n_el, n_out = normals.shape
    weights = np.zeros((n_features, n_out))
    weights[:n_el] = normals * np.asarray(estimator.scales_, dtype=np.float64)
    g = GraphBuilder("weighted_normals", opset)
    x = g.op("Cast", INPUT, to=DOUBLE)
    out = g.op(
        "Gemm",
        x,
        g.const(weights, np.float64),
        g.const(np.asarray(estimator.offsets_, dtype=np.float64), np.float64),
        stem="force",
    )
    return _finish(
        g,
        out,
        n_features=n_features,
        n_outputs=n_out,
        one_d=bool(getattr(estimator, "_y_1d", False)),
        name="WeightedNormalsRegressor",
        doc="WeightedNormalsRegressor: force = x[:, :n_el] @ (normals * scales) + offsets",
    )


def _ridge_blocks(
    estimator: LocalLinearRegressor,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(F, K * O)`` stacked local weights and ``(K * O,)`` biases ``b_k - W_k c_k``."""
    n_out = int(estimator.n_outputs_)
    weights, biases = [], []
    for c, m in zip(estimator.centres_, estimator.local_models_, strict=True):
        coef = np.asarray(m.coef_, dtype=np.float64).reshape(n_out, -1)  # (O, F)
        icpt = np.asarray(m.intercept_, dtype=np.float64).reshape(n_out)
        weights.append(coef.T)
        biases.append(icpt - coef @ np.asarray(c, dtype=np.float64))
    return np.concatenate(weights, axis=1), np.concatenate(biases)


def export_local_linear(
    estimator: LocalLinearRegressor, *, opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Export a fitted :class:`LocalLinearRegressor` (Gemm, Softmax, Mul, ReduceSum in float64).

    Parameters
    ----------
    estimator : LocalLinearRegressor
        Fitted.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Input ``"features"`` ``(batch, n_features_in_)`` float32 (counts), output
        ``"score"``: ``predict`` (N).
    """
    check_is_fitted(estimator)
    scaler = estimator.scaler_
    if scaler.mean_ is None or scaler.scale_ is None:
        raise ExportError("LocalLinearRegressor's scaler has no mean_/scale_")
    n_features = int(estimator.n_features_in_)
    n_out = int(estimator.n_outputs_)
    centres = np.asarray(estimator.centres_, dtype=np.float64)
    k = len(centres)
    h2 = 2.0 * float(estimator.width_) ** 2
    weights, biases = _ridge_blocks(estimator)
    g = GraphBuilder("local_linear", opset)
    x = g.op("Cast", INPUT, to=DOUBLE)
    z = g.op(
        "Mul",
        g.op("Sub", x, g.const(scaler.mean_, np.float64)),
        g.const(1.0 / np.asarray(scaler.scale_, dtype=np.float64), np.float64),
        stem="z",
    )
    axis1 = g.const([1], np.int64)
    zz = g.op("ReduceSum", g.op("Mul", z, z), axis1, keepdims=1, stem="zz")
    # -d^2 / 2h^2 = (2 z C^T - ||C||^2 - ||z||^2) / 2h^2
    cross = g.op(
        "Gemm",
        z,
        g.const(2.0 * centres.T / h2, np.float64),
        g.const(-np.sum(centres * centres, axis=1) / h2, np.float64),
        stem="cross",
    )
    logits = g.op("Sub", cross, g.op("Div", zz, g.const(h2, np.float64)))
    act = g.op("Softmax", logits, axis=1, stem="activation")  # (batch, K)
    local = g.op(
        "Gemm",
        z,
        g.const(weights, np.float64),
        g.const(biases, np.float64),
        stem="local",
    )  # (batch, K * O)
    local3 = g.op("Reshape", local, g.const([0, k, n_out], np.int64))
    act3 = g.op("Unsqueeze", act, g.const([2], np.int64))
    out = g.op("ReduceSum", g.op("Mul", local3, act3), axis1, keepdims=0, stem="force")
    return _finish(
        g,
        out,
        n_features=n_features,
        n_outputs=n_out,
        one_d=bool(getattr(estimator, "_y_1d", False)),
        name="LocalLinearRegressor",
        doc=f"LocalLinearRegressor: {k} Gaussian receptive fields, activation-weighted local ridge models",
    )


register_exporter(WeightedNormalsRegressor, export_weighted_normals)
register_exporter(LocalLinearRegressor, export_local_linear)
