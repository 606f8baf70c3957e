"""Exporter of :class:`slipkit.models.svm.TacTipSVM`: the decision function as MatMul/Exp ops.

skl2onnx writes an SVC as one ``ai.onnx.ml.SVMClassifier`` node, which
onnxruntime evaluates one support vector at a time (~140 us for 1128 SVs x 254
features against ~23 us for numpy matrix products). This exporter
writes the same function with plain ops that map to BLAS calls.

RBF kernel, with ``z = sqrt(gamma) (x - shift) / scale`` (the scaler, if any, and
a centring on the support vectors' mean folded into one Sub and one Mul) and
``s_j = sqrt(gamma) (SV_j - centre)``::

    -gamma ||x - SV_j||^2 = 2 z . s_j - ||s_j||^2 - ||z||^2
    score = sum_j dual_j exp(2 z . s_j - ||s_j||^2 - ||z||^2) + intercept

i.e. ``Gemm(z, 2 S^T, -||S||^2)``, ``Sub`` of ``ReduceSum(z * z)``, ``Exp``, and
``Gemm`` with the dual coefficients and the intercept. Centring keeps ``||z||``
small, so the float32 expansion loses little to cancellation. A linear kernel
collapses to one weight vector ``w = dual_coef @ SV`` (``coef_``), with the
scaler folded in: ``score = x . (w / scale) + intercept - (mean / scale) . w``.

Sign: the score equals ``TacTipSVM.decision_function`` (scikit-learn's public
``dual_coef_`` and ``intercept_`` already carry the binary sign flip), positive
for ``classes_[1]`` ('static' for TacTip frame labels); the decision is
``classes_[1]`` where ``score > 0``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from onnx import helper
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import FLOAT, GraphBuilder
from slipkit.export.pins import (
    PINS_INPUT,
    feature_spec,
    n_features_of,
    pins_from_features,
    velocity_feature_nodes,
)
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    ExportError,
    producers,
    register_exporter,
)
from slipkit.models.svm import TacTipSVM

SCORE = "score"


def _affine(estimator: TacTipSVM) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(mean, scale)`` of the fitted scaler, or ``(0, 1)`` without one."""
    n = int(estimator.n_features_in_)
    scaler = estimator.scaler_
    if scaler is None:
        return np.zeros(n), np.ones(n)
    mean = np.zeros(n) if scaler.mean_ is None else np.asarray(scaler.mean_)
    scale = np.ones(n) if scaler.scale_ is None else np.asarray(scaler.scale_)
    return mean.astype(np.float64), scale.astype(np.float64)


def _rbf_nodes(g: GraphBuilder, x: str, estimator: TacTipSVM) -> str:
    svc = estimator.svc_
    if estimator.gamma_ is None:
        raise ExportError("RBF TacTipSVM without a fitted gamma_")
    gamma = float(estimator.gamma_)
    root = np.sqrt(gamma)
    sv = np.asarray(svc.support_vectors_, dtype=np.float64)
    mean, scale = _affine(estimator)
    centre = sv.mean(axis=0)
    # (x - mean) / scale - centre = (x - (mean + centre * scale)) / scale, times sqrt(gamma).
    shift = mean + centre * scale
    s = root * (sv - centre)
    z = g.op("Mul", g.op("Sub", x, g.const(shift)), g.const(root / scale), stem="z")
    zz = g.op(
        "ReduceSum", g.op("Mul", z, z), g.const([1], np.int64), keepdims=1, stem="zz"
    )
    cross = g.op(
        "Gemm", z, g.const(2.0 * s.T), g.const(-np.sum(s * s, axis=1)), stem="cross"
    )
    # -gamma ||x - sv||^2 <= 0: clamp the expanded form, whose float32 round-off can go
    # slightly positive at a support vector and push the kernel above 1.
    exponent = g.op("Min", g.op("Sub", cross, zz), g.const(np.zeros(1)))
    kernel = g.op("Exp", exponent, stem="kernel")
    dual = np.asarray(svc.dual_coef_, dtype=np.float64).reshape(1, -1)
    return g.op(
        "Gemm",
        kernel,
        g.const(dual.T),
        g.const(np.asarray(svc.intercept_, dtype=np.float64).reshape(1)),
        stem="raw_score",
    )


def _linear_nodes(g: GraphBuilder, x: str, estimator: TacTipSVM) -> str:
    svc = estimator.svc_
    # w = dual_coef @ SV (scikit-learn's coef_ for the linear kernel).
    w = (
        np.asarray(svc.dual_coef_, dtype=np.float64)
        @ np.asarray(svc.support_vectors_, dtype=np.float64)
    ).ravel()
    mean, scale = _affine(estimator)
    w_eff = w / scale
    b_eff = float(np.asarray(svc.intercept_).ravel()[0]) - float(mean @ w_eff)
    return g.op(
        "Gemm",
        x,
        g.const(w_eff.reshape(-1, 1)),
        g.const([b_eff]),
        stem="raw_score",
    )


def export_tactip_svm(
    estimator: TacTipSVM,
    *,
    with_features: bool = False,
    variant: str = "dr_dtheta",
    shift_angles: bool = True,
    missing_count: bool = False,
    n_pins: int | None = None,
    opset: int = DEFAULT_OPSET,
) -> ExportedGraph:
    """Export a fitted binary :class:`TacTipSVM` as plain ONNX ops.

    Parameters
    ----------
    estimator : TacTipSVM
        Fitted, two classes.
    with_features : bool
        Put the pin-velocity features inside the graph: the input becomes
        ``(batch, 2, 2N)`` raw pin positions of the previous and current camera
        frame (mm; :mod:`slipkit.export.pins`), instead of ``(batch, F)`` features.
    variant, shift_angles, missing_count
        The features the SVM was trained on (as
        :func:`slipkit.features.pins.velocity_features`); only read with
        ``with_features``. ``N`` follows from ``n_features_in_``.
    n_pins : int, optional
        Pins per frame of the stream the graph reads. Required for
        ``features="pooled"`` (the input is then per-pin ``dr_dtheta`` features, or
        raw pins with ``with_features``, and the pooled statistics are computed in
        the graph: :func:`slipkit.families.tactip.export.detector.pooled_feature_nodes`); for
        per-pin features it must match the pins the SVM was trained on.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Output ``"score"`` of shape ``(batch,)``, float32: the decision function,
        positive for ``classes_[1]``; threshold 0.
    """
    check_is_fitted(estimator)
    classes = tuple(str(c) for c in estimator.classes_)
    if len(classes) != 2:
        raise ExportError(
            f"TacTipSVM export supports two classes; this one has {len(classes)}: {classes}"
        )
    n_features = int(estimator.n_features_in_)
    g = GraphBuilder("tactip_svm", opset)
    pooled = getattr(estimator, "features", "per_pin") == "pooled"
    if pooled:
        if n_pins is None or variant != "dr_dtheta" or missing_count:
            raise ExportError(
                "a pooled TacTipSVM needs n_pins (the stream's pin count), "
                "variant='dr_dtheta' and no missing_count; got "
                f"n_pins={n_pins}, variant={variant!r}, missing_count={missing_count}"
            )
        n_features = 2 * int(n_pins) + int(missing_count)
    elif n_pins is not None and n_features != n_features_of(
        int(n_pins), variant, missing_count
    ):
        raise ExportError(
            f"the SVM was trained on {n_features} per-pin features "
            f"({pins_from_features(n_features, variant, missing_count)} pins); the "
            f"stream has {n_pins} pins: retrain, or use features='pooled'"
        )
    if with_features:
        n_pins = pins_from_features(n_features, variant, missing_count)
        x = velocity_feature_nodes(
            g,
            PINS_INPUT,
            n_pins,
            variant=variant,
            shift_angles=shift_angles,
            missing_count=missing_count,
        )
        inp = helper.make_tensor_value_info(PINS_INPUT, FLOAT, ["batch", 2, 2 * n_pins])
        input_shape: tuple[str | int, ...] = ("batch", 2, 2 * n_pins)
        meaning = "previous and current frame of x0..x{N-1}, y0..y{N-1} (mm, NaN: pin not detected)"
        features: dict[str, Any] | None = feature_spec(
            n_pins, variant, shift_angles, missing_count
        )
    else:
        x = "features"
        inp = helper.make_tensor_value_info(x, FLOAT, ["batch", n_features])
        input_shape = ("batch", n_features)
        names = getattr(estimator, "feature_names_in_", None)
        meaning = (
            f"{n_features} pin-velocity features"
            if names is None
            else "features " + ", ".join(map(str, names))
        )
        features = None
    if pooled:
        from slipkit.families.tactip.export.detector import (
            pooled_feature_nodes,
            pooled_spec,
        )

        x = pooled_feature_nodes(g, x, int(n_pins or 0))
        features = {**(features or {}), **pooled_spec(int(n_pins or 0))}
    if estimator.kernel == "rbf":
        raw = _rbf_nodes(g, x, estimator)
    elif estimator.kernel == "linear":
        raw = _linear_nodes(g, x, estimator)
    else:
        raise ExportError(f"TacTipSVM kernel {estimator.kernel!r} is not exportable")
    g.nodes.append(helper.make_node("Reshape", [raw, g.const([-1], np.int64)], [SCORE]))
    model = g.build(
        [inp],
        [helper.make_tensor_value_info(SCORE, FLOAT, ["batch"])],
        doc=f"TacTipSVM ({estimator.kernel} kernel, {estimator.svc_.support_vectors_.shape[0]} SVs) decision function",
    )
    import sklearn

    return ExportedGraph(
        model=model,
        input_name=inp.name,
        input_shape=input_shape,
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning=f"decision_function: positive for classes_[1] ({classes[1]!r}); "
        f"{classes[0]!r} where score <= 0",
        score_method="decision_function",
        opset=g.opset,
        classes=classes,
        threshold=0.0,
        input_meaning=meaning,
        features=features,
        producers=producers(**{"scikit-learn": sklearn.__version__}),
    )


register_exporter(TacTipSVM, export_tactip_svm)
