"""The DAVIS polarity rule as a tiny graph on the filtered areas (Rigi et al. 2018, Sec. 3.2).

The DAVIS detector's area filter needs connected components, which ONNX has no op
for: the runtime's ``davis_areas`` preprocessing op
(:mod:`slipkit.runtime.preprocessing`) turns each 10 ms event frame into the filtered
positive and negative areas (px), and the graph holds only the polarity rule on them:
slip when ``pos > 0`` and ``pos >= neg``.

:class:`DavisAreaRule` is that rule as a scikit-learn classifier on ``(pos, neg)``
rows, so the export parity check compares it with its graph; the deployer
(:func:`slipkit.families.davis.deploy._deploy_davis`) checks the op's areas against the
detector's own (``DavisPolarity.frames``) on the held-out trials.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from onnx import helper
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    producers,
    register_exporter,
)

INPUT = "areas"
SCORE = "score"


class DavisAreaRule(ClassifierMixin, BaseEstimator):
    """The polarity rule on filtered areas: slip when ``pos > 0`` and ``pos >= neg``.

    ``X`` rows are ``(pos_area_px, neg_area_px)`` (whole pixels). The score
    ``min(pos - 0.5, pos - neg + 0.5)`` is > 0 exactly when the rule says slip (areas
    are integers), 0.5 px from the threshold at the nearest integer case.

    Attributes
    ----------
    classes_ : ndarray
        ``[0, 1]`` (1 = slip), as :class:`slipkit.families.davis.polarity.DavisPolarity`.
    n_features_in_ : int
        2.
    """

    def fit(
        self, X: ArrayLike | None = None, y: ArrayLike | None = None
    ) -> DavisAreaRule:
        """Nothing to learn: record the classes."""
        del X, y
        self.classes_ = np.array([0, 1])
        self.n_features_in_ = 2
        return self

    def decision_function(self, X: ArrayLike) -> NDArray[np.float64]:
        """``min(pos - 0.5, pos - neg + 0.5)`` (px): > 0 is slip."""
        check_is_fitted(self, "classes_")
        a = np.asarray(X, dtype=np.float64).reshape(-1, 2)
        pos, neg = a[:, 0], a[:, 1]
        return np.minimum(pos - 0.5, pos - neg + 0.5)

    def predict(self, X: ArrayLike) -> NDArray[np.int_]:
        """1 (slip) where the score is > 0, else 0."""
        return (self.decision_function(X) > 0).astype(int)


def export_davis_rule(
    estimator: DavisAreaRule, *, opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Export :class:`DavisAreaRule`: two float64 ``Gemm`` rows and a ``Min``.

    Returns
    -------
    ExportedGraph
        Input ``"areas"`` ``(batch, 2)`` float32 (filtered positive, negative area,
        px), output ``"score"`` ``(batch,)``: the rule's decision function.
    """
    check_is_fitted(estimator, "classes_")
    g = GraphBuilder("davis_area_rule", opset)
    x = g.op("Cast", INPUT, to=DOUBLE)
    a = g.op(
        "Gemm",
        x,
        g.const([[1.0], [0.0]], np.float64),
        g.const([-0.5], np.float64),
        stem="pos",
    )
    b = g.op(
        "Gemm",
        x,
        g.const([[1.0], [-1.0]], np.float64),
        g.const([0.5], np.float64),
        stem="pos_minus_neg",
    )
    out = g.op("Cast", g.op("Min", a, b), to=FLOAT)
    g.nodes.append(helper.make_node("Reshape", [out, g.const([-1], np.int64)], [SCORE]))
    model = g.build(
        [helper.make_tensor_value_info(INPUT, FLOAT, ["batch", 2])],
        [helper.make_tensor_value_info(SCORE, FLOAT, ["batch"])],
        doc="DAVIS polarity rule: min(pos - 0.5, pos - neg + 0.5) > 0 is slip",
    )
    import sklearn

    return ExportedGraph(
        model=model,
        input_name=INPUT,
        input_shape=("batch", 2),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning="DavisAreaRule.decision_function: > 0 is slip (px)",
        score_method="decision_function",
        opset=g.opset,
        classes=tuple(str(c) for c in estimator.classes_),
        threshold=0.0,
        input_meaning="filtered positive and negative event areas of one 10 ms frame (px)",
        producers=producers(**{"scikit-learn": sklearn.__version__}),
    )


register_exporter(DavisAreaRule, export_davis_rule)

__all__ = ["DavisAreaRule", "export_davis_rule"]
