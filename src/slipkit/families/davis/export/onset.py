"""Exporter of the DAVIS onset rule (:mod:`slipkit.families.davis.onset`).

The whole rule fits in one graph on the runtime's event frame (counts per pixel,
``(batch, 2, H, W)``, positive then negative), no preprocessing op:

1. in float32 (every value a small whole number, so exact): ``fired = frame > 0``;
   one ``Conv`` grouped by polarity, a 3 x 3 kernel of ones with 9 at the centre and
   a bias of ``-(8 + min_neighbours)``, clipped to [0, 1]: the kept pixels (fired
   with at least ``min_neighbours`` fired 8-neighbours); per row, ``MatMul`` with
   ``[1, x, x^2]`` (kept pixels and their sums of x and x^2);
2. in float64, on those ``(batch, 2, H, 3)`` row sums only: ``MatMul`` with
   ``[1, y, y^2]`` gives every area and first and second moment, then the positive
   pixels' covariance and its ``curl`` in the order of ``onset_features``;
3. the score :func:`~slipkit.families.davis.onset.onset_score`: > 0 is slip.

:class:`DavisOnsetScores` is the estimator side of the parity check (the detector's
numpy features and score on runtime frames); the deployer checks those features equal
the detector's own (``DavisOnset.frames`` on the events) on every held-out frame
(:func:`slipkit.families.davis.deploy.deploy_davis_onset`).
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
from slipkit.families.davis.onset import NEIGHBOURS, DavisOnset

INPUT = "event_frame"
SCORE = "score"


class DavisOnsetScores(ClassifierMixin, BaseEstimator):
    """A :class:`DavisOnset` scoring runtime event frames ``(n, 2, H, W)``.

    Parameters
    ----------
    detector : DavisOnset
        Fitted.
    """

    def __init__(self, *, detector: DavisOnset) -> None:
        self.detector = detector

    def fit(
        self, X: ArrayLike | None = None, y: ArrayLike | None = None
    ) -> DavisOnsetScores:
        """Check the detector is fitted (no data used)."""
        del X, y
        check_is_fitted(self.detector, "classes_")
        self.classes_ = np.array([0, 1])
        return self

    def _frames(self, frames: ArrayLike) -> NDArray[np.float64]:
        d = self.detector
        return np.asarray(frames, dtype=np.float64).reshape(
            -1, 2, int(d.height_px), int(d.width_px)
        )

    def features(self, frames: ArrayLike) -> NDArray[np.float64]:
        """The detector's features of event frames."""
        return self.detector.features(self._frames(frames))

    def decision_function(self, frames: ArrayLike) -> NDArray[np.float64]:
        """The onset score per frame: > 0 is slip."""
        check_is_fitted(self, "classes_")
        return self.detector.score(self.features(frames))

    def predict(self, frames: ArrayLike) -> NDArray[np.int_]:
        """1 (slip) where the score is > 0, else 0."""
        return (self.decision_function(frames) > 0).astype(int)


def export_davis_onset(
    scores: DavisOnsetScores, *, opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Export :class:`DavisOnsetScores` (module docstring).

    Returns
    -------
    ExportedGraph
        Input ``"event_frame"`` ``(batch, 2, H, W)`` float32 (counts per pixel), output
        ``"score"`` ``(batch,)``: the onset score, > 0 is slip.
    """
    check_is_fitted(scores, "classes_")
    d = scores.detector
    h, w = int(d.height_px), int(d.width_px)
    g = GraphBuilder("davis_onset_rule", opset)
    # 1. whole-image work in float32 (every value a small whole number, exact): the
    #    fired pixels, then 9 x fired + fired 8-neighbours - (8 + min_neighbours) as
    #    one Conv grouped by polarity (>= 1 exactly when the pixel fired with enough
    #    fired neighbours: the neighbours alone are <= 8), clipped to the kept mask.
    #    Grouped, the Conv keeps onnxruntime's plain kernel (a one-channel Conv on a
    #    (2 batch, 1, H, W) reshape is laid out to NCHWc and back, twice as slow).
    fired = g.op("Cast", g.op("Greater", INPUT, g.const(0.0)), to=FLOAT)
    kernel = NEIGHBOURS + 9.0 * (NEIGHBOURS == 0)
    bias = -8.0 - float(d.min_neighbours)
    count = g.op(
        "Conv",
        fired,
        g.const(np.stack([kernel[None], kernel[None]])),  # (2, 1, 3, 3)
        g.const([bias, bias]),
        pads=[1, 1, 1, 1],
        group=2,
        stem="nb",
    )
    keep = g.op("Clip", count, g.const(0.0), g.const(1.0), stem="keep")
    # per row: kept pixels, their sum of x and of x^2 (<= 190, 18 000, 2.3e6: exact)
    x = np.arange(w, dtype=np.float64)
    per_row = g.op(
        "MatMul", keep, g.const(np.stack([np.ones(w), x, x * x], axis=1))
    )  # (b, 2, H, 3)
    # 2. in float64 on the reduced (b, 2, H, 3): [1, y, y^2] over the rows gives
    #    M[p, i, j] = sum of y^i x^j over the kept pixels of polarity p
    y = np.arange(h, dtype=np.float64)
    moments = g.op(
        "MatMul",
        g.const(np.stack([np.ones(h), y, y * y]), np.float64),
        g.op("Cast", per_row, to=DOUBLE),
    )  # (b, 2, 3, 3)
    flat_m = g.op("Reshape", moments, g.const([-1, 18], np.int64))
    names = [g._fresh("m") for _ in range(18)]
    g.nodes.append(
        helper.make_node("Split", [flat_m, g.const([1] * 18, np.int64)], names, axis=1)
    )
    pos_area, sx, sxx = names[0], names[1], names[2]  # (b, 1) each
    sy, sxy, syy = names[3], names[4], names[6]
    neg_area = names[9]
    n = g.op("Max", pos_area, g.const([1.0], np.float64))
    # the order of onset_features' operations (same rounding on the same sums)
    mx, my = g.op("Div", sx, n), g.op("Div", sy, n)
    vx = g.op("Sub", g.op("Div", sxx, n), g.op("Mul", mx, mx))
    vy = g.op("Sub", g.op("Div", syy, n), g.op("Mul", my, my))
    cxy = g.op("Sub", g.op("Div", sxy, n), g.op("Mul", mx, my))
    det_c = g.op("Sub", g.op("Mul", vx, vy), g.op("Mul", cxy, cxy))
    root = g.op("Sqrt", g.op("Max", det_c, g.const([0.0], np.float64)))
    curl = g.op("Div", g.op("Mul", root, g.const([12.0], np.float64)), n, stem="curl")
    half = g.const([0.5], np.float64)
    t1 = g.op("Add", pos_area, g.const([0.5 - float(d.min_pos_px)], np.float64))
    t2 = g.op(
        "Add",
        g.op(
            "Sub",
            g.op("Mul", pos_area, g.const([float(d.neg_ratio)], np.float64)),
            neg_area,
        ),
        half,
    )
    t3 = g.op("Sub", g.const([float(d.max_curl)], np.float64), curl)
    out = g.op("Cast", g.op("Min", t1, t2, t3), to=FLOAT)
    g.nodes.append(helper.make_node("Reshape", [out, g.const([-1], np.int64)], [SCORE]))
    model = g.build(
        [helper.make_tensor_value_info(INPUT, FLOAT, ["batch", 2, h, w])],
        [helper.make_tensor_value_info(SCORE, FLOAT, ["batch"])],
        doc=(
            f"DAVIS onset rule: min(pos - {d.min_pos_px} + 0.5, {d.neg_ratio:g} pos - "
            f"neg + 0.5, {d.max_curl:g} - curl) > 0 is slip"
        ),
    )
    import sklearn

    return ExportedGraph(
        model=model,
        input_name=INPUT,
        input_shape=("batch", 2, h, w),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning="DavisOnsetScores.decision_function: > 0 is slip",
        score_method="decision_function",
        opset=g.opset,
        classes=("0", "1"),
        threshold=0.0,
        input_meaning="one event frame, counts per pixel, positive then negative",
        producers=producers(**{"scikit-learn": sklearn.__version__}),
    )


register_exporter(DavisOnsetScores, export_davis_onset)


__all__ = ["DavisOnsetScores", "export_davis_onset"]
