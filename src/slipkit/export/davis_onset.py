"""The DAVIS onset rule as a tiny graph on the filtered areas, and its deployment.

As the polarity rule (:mod:`slipkit.export.davis`): the runtime's ``davis_areas`` op
gives each event frame's filtered positive and negative areas (ONNX has no connected
components) and the graph holds the decision, here
:func:`slipkit.baselines.davis_onset.onset_score`:
``min(pos - min_pos_px + 0.5, neg_ratio pos - neg + 0.5)`` > 0 is slip.
:class:`DavisOnsetAreaRule` is that score as a scikit-learn classifier on ``(pos, neg)``
rows, for the export parity check; :func:`deploy_davis_onset` is the deployer's branch for
:class:`~slipkit.baselines.davis_onset.DavisOnset` runs.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from onnx import helper
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.davis_onset import onset_score
from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    producers,
    register_exporter,
)

INPUT = "areas"
SCORE = "score"


class DavisOnsetAreaRule(ClassifierMixin, BaseEstimator):
    """:func:`~slipkit.baselines.davis_onset.onset_score` on ``(pos, neg)`` rows (px).

    Parameters
    ----------
    min_pos_px : int
        Smallest filtered positive area of a slip frame (px).
    neg_ratio : float
        Largest negative area per px of positive area (a binary fraction such as 0.25
        keeps the graph's arithmetic exact).
    """

    def __init__(self, min_pos_px: int = 8, neg_ratio: float = 0.25) -> None:
        self.min_pos_px = min_pos_px
        self.neg_ratio = neg_ratio

    def fit(
        self, X: ArrayLike | None = None, y: ArrayLike | None = None
    ) -> DavisOnsetAreaRule:
        """Nothing to learn: record the classes."""
        del X, y
        self.classes_ = np.array([0, 1])
        self.n_features_in_ = 2
        return self

    def decision_function(self, X: ArrayLike) -> NDArray[np.float64]:
        """The onset score (px): > 0 is slip."""
        check_is_fitted(self, "classes_")
        a = np.asarray(X, dtype=np.float64).reshape(-1, 2)
        return onset_score(
            a[:, 0],
            a[:, 1],
            min_pos_px=int(self.min_pos_px),
            neg_ratio=float(self.neg_ratio),
        )

    def predict(self, X: ArrayLike) -> NDArray[np.int_]:
        """1 (slip) where the score is > 0, else 0."""
        return (self.decision_function(X) > 0).astype(int)


def export_davis_onset_rule(
    estimator: DavisOnsetAreaRule, *, opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Export :class:`DavisOnsetAreaRule`: two float64 ``Gemm`` rows and a ``Min``.

    Returns
    -------
    ExportedGraph
        Input ``"areas"`` ``(batch, 2)`` float32 (filtered positive, negative area,
        px), output ``"score"`` ``(batch,)``: the rule's decision function.
    """
    check_is_fitted(estimator, "classes_")
    g = GraphBuilder("davis_onset_rule", opset)
    x = g.op("Cast", INPUT, to=DOUBLE)
    a = g.op(
        "Gemm",
        x,
        g.const([[1.0], [0.0]], np.float64),
        g.const([0.5 - float(estimator.min_pos_px)], np.float64),
        stem="pos",
    )
    b = g.op(
        "Gemm",
        x,
        g.const([[float(estimator.neg_ratio)], [-1.0]], np.float64),
        g.const([0.5], np.float64),
        stem="one_sided",
    )
    out = g.op("Cast", g.op("Min", a, b), to=FLOAT)
    g.nodes.append(helper.make_node("Reshape", [out, g.const([-1], np.int64)], [SCORE]))
    model = g.build(
        [helper.make_tensor_value_info(INPUT, FLOAT, ["batch", 2])],
        [helper.make_tensor_value_info(SCORE, FLOAT, ["batch"])],
        doc=(
            f"DAVIS onset rule: min(pos - {estimator.min_pos_px} + 0.5, "
            f"{estimator.neg_ratio} pos - neg + 0.5) > 0 is slip"
        ),
    )
    import sklearn

    return ExportedGraph(
        model=model,
        input_name=INPUT,
        input_shape=("batch", 2),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning="DavisOnsetAreaRule.decision_function: > 0 is slip (px)",
        score_method="decision_function",
        opset=g.opset,
        classes=tuple(str(c) for c in estimator.classes_),
        threshold=0.0,
        input_meaning="filtered positive and negative event areas of one event frame (px)",
        producers=producers(**{"scikit-learn": sklearn.__version__}),
    )


register_exporter(DavisOnsetAreaRule, export_davis_onset_rule)


def deploy_davis_onset(
    task: Any, run: Any, dataset: Any, options: Mapping[str, Any]
) -> Any:
    """A :class:`~slipkit.baselines.davis_onset.DavisOnset` run's deployment.

    The polarity rule's (``davis_areas`` op, its areas checked equal to the detector's
    on every held-out frame) with the onset rule's graph and frame; debounce from the
    options (default 2: a loss of contact that lasts two frames).
    """
    import dataclasses

    from slipkit.export.deploy_davis import deploy_area_rule

    det = run.model
    dep = deploy_area_rule(
        task,
        run,
        dataset,
        options,
        DavisOnsetAreaRule(
            min_pos_px=int(det.min_pos_px), neg_ratio=float(det.neg_ratio)
        ).fit(),
    )
    notes = [n for n in dep.notes if not n.startswith("decision:")]
    notes.append(
        f"decision: slip when positive area >= {det.min_pos_px} px and negative area "
        f"<= {det.neg_ratio:g} x positive (one-sided loss of contact; the graph)"
    )
    return dataclasses.replace(
        dep, notes=notes, debounce_k=int(options.get("debounce_k") or 2)
    )


__all__ = ["DavisOnsetAreaRule", "deploy_davis_onset", "export_davis_onset_rule"]
