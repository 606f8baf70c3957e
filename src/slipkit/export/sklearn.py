"""Generic exporter of plain scikit-learn estimators and Pipelines through skl2onnx.

Registered for every class skl2onnx can convert (its
``sklearn_operator_name_map``: linear models, scalers, SVMs, trees, Pipeline,
ColumnTransformer, ...). slipkit's own estimators register their own exporters
(e.g. :mod:`slipkit.families.tactip.export.svm`), which win because they sit earlier in the MRO.

The score
---------
* Classifiers with ``predict_proba``: skl2onnx's ``probabilities`` output
  (``zipmap`` off), ``(batch, n_classes)`` in ``classes_`` order; decision = arg-max.
* Binary classifiers without ``predict_proba`` (``SVC(probability=False)``,
  ``LinearSVC``, ``RidgeClassifier``): skl2onnx's second output holds the
  decision function in **column 0** -- for ``SVC`` it is ``(batch, 2)`` as
  ``[df, -df]`` (the column is *not* the score of ``classes_[0]``, whatever its
  position suggests), for linear classifiers ``(batch, 1)``. A ``Gather`` of
  column 0 is appended as output ``"score"``, shape ``(batch,)``, equal to
  ``decision_function`` (positive for ``classes_[1]``, threshold 0).
* Regressors and transformers: ``predict`` / ``transform`` output ``variable``,
  ``(batch, n_outputs)``.

Multi-class classifiers without ``predict_proba`` are refused: skl2onnx's scores
there do not follow one documented convention. A Pipeline whose last step is a
skorch net goes to :func:`slipkit.export.torch.export_skorch_estimator`.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import onnx
from onnx import helper, numpy_helper
from sklearn.base import is_classifier, is_regressor
from sklearn.utils.validation import check_is_fitted

from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    ExportError,
    ScoreMethod,
    check_opset,
    finalize_model,
    input_spec,
    producers,
    register_exporter,
)

INPUT = "X"
SCORE = "score"


def _n_features(estimator: Any, n_features: int | None) -> int:
    if n_features is not None:
        return int(n_features)
    n = getattr(estimator, "n_features_in_", None)
    if n is None:
        raise ExportError(
            f"{type(estimator).__name__} does not record n_features_in_; pass n_features="
        )
    return int(n)


def _append_score_column(model: onnx.ModelProto, scores: str) -> None:
    """Add output ``score`` = column 0 of ``scores`` (shape ``(batch,)``)."""
    graph = model.graph
    index = numpy_helper.from_array(np.asarray(0, dtype=np.int64), "score_column")
    graph.initializer.append(index)
    graph.node.append(
        helper.make_node("Gather", [scores, "score_column"], [SCORE], axis=1)
    )
    graph.output.append(
        helper.make_tensor_value_info(SCORE, onnx.TensorProto.FLOAT, ["batch"])
    )


def export_sklearn(
    estimator: Any,
    *,
    n_features: int | None = None,
    opset: int = DEFAULT_OPSET,
    options: dict[Any, Any] | None = None,
) -> ExportedGraph:
    """Convert a fitted scikit-learn estimator or Pipeline with skl2onnx.

    Parameters
    ----------
    estimator : sklearn estimator
        Fitted; every step must be convertible by skl2onnx.
    n_features : int, optional
        Input width; default ``estimator.n_features_in_``.
    opset : int
        Default-domain opset (17 or 18); ``ai.onnx.ml`` stays at 3.
    options : dict, optional
        Extra skl2onnx converter options (``{id(step): {...}}``), merged over
        ``zipmap=False`` for classifiers with ``predict_proba``.

    Returns
    -------
    ExportedGraph
        Float32 input ``"X"`` of shape ``(batch, n_features)``; the score as
        described in the module notes.
    """
    import skl2onnx
    import sklearn
    from skl2onnx import to_onnx
    from skl2onnx.common.data_types import FloatTensorType

    check_is_fitted(estimator)
    opset = check_opset(opset)
    steps = getattr(estimator, "steps", None)
    if steps and hasattr(steps[-1][1], "module_"):
        # A Pipeline of scalers ending in a skorch net: skl2onnx cannot convert the
        # net, the torch exporter folds the scalers in (find_torch_parts).
        from slipkit.export.torch import export_skorch_estimator

        return export_skorch_estimator(estimator, opset=opset)
    n = _n_features(estimator, n_features)
    classes: Any = getattr(estimator, "classes_", None)
    classifier = is_classifier(estimator) and classes is not None
    proba = classifier and hasattr(estimator, "predict_proba")
    if classifier and not proba and len(classes) != 2:
        raise ExportError(
            f"{type(estimator).__name__} has {len(classes)} classes and no predict_proba; "
            "only binary decision functions are exported"
        )
    final = estimator.steps[-1][1] if hasattr(estimator, "steps") else estimator

    def convert(zipmap_off: bool) -> onnx.ModelProto:
        opts: dict[Any, Any] = {id(final): {"zipmap": False}} if zipmap_off else {}
        opts.update(options or {})
        with warnings.catch_warnings():
            # skl2onnx reads SVC's probA_/probB_, deprecated in scikit-learn 1.9.
            warnings.simplefilter("ignore", FutureWarning)
            return to_onnx(
                estimator,
                initial_types=[(INPUT, FloatTensorType([None, n]))],
                target_opset={"": opset, "ai.onnx.ml": 3},
                options=opts or None,
            )

    try:
        # A tensor of scores rather than a list of {class: score} maps.
        model = convert(zipmap_off=classifier)
    except NameError:  # skl2onnx's way of saying this converter has no zipmap option
        model = convert(zipmap_off=False)
    # skl2onnx names the batch dimension "N" or leaves it unnamed; name it "batch".
    dim0 = model.graph.input[0].type.tensor_type.shape.dim[0]
    dim0.dim_param = "batch"
    outputs = [o.name for o in model.graph.output]
    score_method: ScoreMethod
    threshold: float | None = None
    if proba:
        score_output = outputs[1]
        score_method = "predict_proba"
        meaning = "probabilities in classes_ order"
    elif classifier:
        _append_score_column(model, outputs[1])
        score_output = SCORE
        score_method = "decision_function"
        threshold = 0.0
        meaning = (
            f"decision_function (column 0 of skl2onnx's {outputs[1]!r}): "
            f"positive for classes_[1] ({classes[1]!r})"
        )
    elif is_regressor(estimator):
        score_output = outputs[0]
        score_method = "predict"
        meaning = "regression outputs of predict"
    else:
        score_output = outputs[0]
        score_method = "transform"
        meaning = "transform output"
    model = finalize_model(model)
    name, shape = input_spec(model)
    return ExportedGraph(
        model=model,
        input_name=name,
        input_shape=shape,
        output_names=tuple(o.name for o in model.graph.output),
        score_output=score_output,
        score_meaning=meaning,
        score_method=score_method,
        opset=opset,
        classes=None if not classifier else tuple(str(c) for c in classes),
        threshold=threshold,
        input_meaning=f"{n} features",
        producers=producers(
            **{"scikit-learn": sklearn.__version__, "skl2onnx": skl2onnx.__version__}
        ),
    )


def _register() -> None:
    from skl2onnx._supported_operators import sklearn_operator_name_map

    # skl2onnx's own table of convertible scikit-learn classes (its private name,
    # but the same table its public `supported_converters` is built from).
    for cls in sklearn_operator_name_map:
        if isinstance(cls, type) and cls.__module__.startswith("sklearn."):
            register_exporter(cls, export_sklearn)


_register()
