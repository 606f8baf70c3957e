"""Exporters of the analytic BioTac force models: hand-built graphs of few nodes.

* :class:`~slipkit.families.biotac.force.WeightedNormalsRegressor` -- ``F_k = S_k sum_i E_i
  N_k,i + o_k`` is one matrix product: ``Gemm(x, W, o)`` in float32 with ``W[i, k] =
  N_k,i S_k`` for the electrode columns and zero rows for any extra input column (the
  model reads only its electrodes); the graph is that one node.
* :class:`~slipkit.families.biotac.force.LocalLinearRegressor` -- with ``z = (x - mean) /
  scale``, the receptive-field activations are ``softmax(-||z - c_k||^2 / 2 h^2)`` =
  ``softmax((2 z C^T - ||C||^2) / 2 h^2)`` (``||z||^2`` is the same for every field of
  a row, and softmax ignores a per-row constant): one ``Gemm``; every local ridge
  model ``W_k (z - c_k) + b_k`` is one column block of ``z @ [W_1^T .. W_K^T] + [b_k -
  W_k c_k]``: a second ``Gemm``, its columns output-major. The scaler is folded into
  both Gemms' weights and biases, and the activation-weighted sum over fields is one
  batched ``MatMul`` of the local outputs as ``(batch, O, K)`` with the activations
  as ``(batch, K, 1)`` (``Reshape`` s around it): seven nodes where the step-by-step
  form had seventeen (node dispatch, ~0.2 us each, not arithmetic, dominates a
  batch-1 call).

The LWR graph reads and writes float64 (the runtime feeds a float64 frame and reads
a float64 force: no cast nodes): the electrode inputs are counts of order
10^2-10^3, and with the scaler folded in the Gemms cancel what the scaler's
subtraction did, so float32 arithmetic would lose digits wherever the counts sit far
from the scaler's mean relative to its scale. The output is ``predict`` (N), shape ``(batch, n_outputs)``
(``(batch,)`` for a model fitted on a 1-D target).

:class:`~slipkit.families.biotac.force.ForceMLP` (a torch module and its scalers) exports
through :func:`slipkit.export.torch.export_skorch_estimator`.
"""

from __future__ import annotations

import numpy as np
import onnx
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
from slipkit.export.torch import export_skorch_estimator
from slipkit.families.biotac.force import (
    ForceMLP,
    LocalLinearRegressor,
    WeightedNormalsRegressor,
)

INPUT = "features"
SCORE = "score"


def _finish(
    g: GraphBuilder,
    out: str,
    *,
    n_features: int,
    n_outputs: int,
    one_d: bool,
    name: str,
    doc: str,
) -> ExportedGraph:
    """A float32 graph: flatten a 1-D model's output, build, wrap as an ExportedGraph.
    The last node writes ``score`` itself (no Identity)."""
    if one_d:
        g.nodes.append(
            helper.make_node("Reshape", [out, g.const([-1], np.int64)], [SCORE])
        )
        out_shape: list[str | int] = ["batch"]
    else:
        last = g.nodes[-1]
        if list(last.output) == [out]:
            last.output[0] = SCORE
        else:
            g.rename(out, SCORE)
        out_shape = ["batch", n_outputs]
    model = g.build(
        [helper.make_tensor_value_info(INPUT, FLOAT, ["batch", n_features])],
        [helper.make_tensor_value_info(SCORE, FLOAT, out_shape)],
        doc=doc,
    )
    return _graph(
        model, n_features=n_features, n_outputs=n_outputs, name=name, opset=g.opset
    )


def _graph(
    model: onnx.ModelProto,
    *,
    n_features: int,
    n_outputs: int,
    name: str,
    opset: int,
    input_dtype: str = "float32",
) -> ExportedGraph:
    import sklearn

    return ExportedGraph(
        model=model,
        input_name=INPUT,
        input_shape=("batch", n_features),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning=f"{name}.predict: force (N), {n_outputs} output(s)",
        score_method="predict",
        opset=opset,
        input_meaning=f"{n_features} electrode values (counts), as the model was fitted",
        producers=producers(**{"scikit-learn": sklearn.__version__}),
        input_dtype=input_dtype,
    )


def export_weighted_normals(
    estimator: WeightedNormalsRegressor, *, opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Export a fitted :class:`WeightedNormalsRegressor` as one float32 ``Gemm``.

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
    # one float32 Gemm, the graph's only node: the float64 casts around it cost more
    # than they buy (float32 rounding of a dozen count x weight products, ~1e-6 N for
    # forces of a few N, far inside the parity tolerance)
    g = GraphBuilder("weighted_normals", opset)
    out = g.op(
        "Gemm",
        INPUT,
        g.const(weights, np.float32),
        g.const(np.asarray(estimator.offsets_, dtype=np.float64), np.float32),
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
    """Export a fitted :class:`LocalLinearRegressor` (two Gemms, Softmax, a batched MatMul; float64).

    Parameters
    ----------
    estimator : LocalLinearRegressor
        Fitted.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Input ``"features"`` ``(batch, n_features_in_)`` float64 (counts), output
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
    # Fewer nodes (node dispatch, not arithmetic, dominates a batch-1 call): the
    # scaler folds into both Gemms (z = (x - m) / s, so z A + a = x (A / s) + (a - (m /
    # s) A)), and the softmax drops ||z||^2 / 2h^2, the same for every field of a row
    # (softmax is invariant to a per-row constant; it subtracts the row maximum itself).
    # Both Gemms read the float64 counts: folded, they hold the cancellation the
    # scaler's Sub did, so float32 would lose digits here.
    mean = np.asarray(scaler.mean_, dtype=np.float64)
    inv = 1.0 / np.asarray(scaler.scale_, dtype=np.float64)

    def folded(a: NDArray[np.float64], bias: NDArray[np.float64]) -> tuple[str, str]:
        a_x = a * inv[:, None]
        return g.const(a_x, np.float64), g.const(bias - mean @ a_x, np.float64)

    g = GraphBuilder("local_linear", opset)
    # float64 in and out: the runtime feeds the float64 frame and reads a float64
    # force, so there is no cast node at either end.
    x = INPUT
    # logits = -d^2 / 2h^2 + ||z||^2 / 2h^2 = (2 z C^T - ||C||^2) / 2h^2
    logits = g.op(
        "Gemm",
        x,
        *folded(2.0 * centres.T / h2, -np.sum(centres * centres, axis=1) / h2),
        stem="logits",
    )
    act = g.op("Softmax", logits, axis=1, stem="activation")  # (batch, K)
    # The local models' outputs output-major, (batch, O * K): column o K + k is
    # field k's output o, so a Reshape makes them (batch, O, K) and one batched MatMul
    # with the activations as (batch, K, 1) is sum_k act_k local_k,o. Faster in
    # scratch timings (one thread, batch 1) than (act @ R) * local @ S with 0/1
    # matrices R, S, and far faster than one Einsum over act, [x, 1] and the stacked
    # weights (onnxruntime's Einsum is slow); a Reshape costs only its dispatch.
    order = np.arange(k * n_out).reshape(k, n_out).T.reshape(-1)
    local = g.op(
        "Gemm", x, *folded(weights[:, order], biases[order]), stem="local"
    )  # (batch, O * K)
    local3 = g.op("Reshape", local, g.const([-1, n_out, k], np.int64), stem="local3")
    act3 = g.op("Reshape", act, g.const([-1, k, 1], np.int64), stem="activation3")
    out = g.op("MatMul", local3, act3, stem="force")  # (batch, O, 1)
    one_d = bool(getattr(estimator, "_y_1d", False))
    shape = [-1] if one_d else [-1, n_out]
    g.nodes.append(
        helper.make_node("Reshape", [out, g.const(shape, np.int64)], [SCORE])
    )
    model = g.build(
        [helper.make_tensor_value_info(INPUT, DOUBLE, ["batch", n_features])],
        [
            helper.make_tensor_value_info(
                SCORE, DOUBLE, ["batch"] if one_d else ["batch", n_out]
            )
        ],
        doc=f"LocalLinearRegressor: {k} Gaussian receptive fields, activation-weighted local ridge models",
    )
    return _graph(
        model,
        n_features=n_features,
        n_outputs=n_out,
        name="LocalLinearRegressor",
        opset=g.opset,
        input_dtype="float64",
    )


register_exporter(WeightedNormalsRegressor, export_weighted_normals)
register_exporter(LocalLinearRegressor, export_local_linear)
# ForceMLP keeps a torch module and its scalers (not a skorch NeuralNet): the skorch exporter
register_exporter(ForceMLP, export_skorch_estimator)
