"""Exporter of the learned DAVIS event-frame classifier.

:class:`~slipkit.families.davis.classifier.EventFrameClassifier` reads, per ``frame_s`` frame of
events, the positive and negative event counts and areas (distinct pixels that fired)
and feeds six numbers of them (:func:`~slipkit.families.davis.classifier.event_features`) to a
``StandardScaler`` -> ``LogisticRegression`` pipeline. The runtime receives each frame
as counts per pixel, shape ``(2, height_px, width_px)`` (positive, negative; the DAVIS
deployer's :func:`~slipkit.families.davis.deploy.davis_event_frames`), so the whole estimator
fits in one graph:

1. **features** (ONNX ops): the counts are a ``ReduceSum`` of the frame and the areas a
   ``ReduceSum`` of ``frame > 0`` (both in float32, exact for whole counts below 2^24),
   then in float64 ``log(1 + .)`` and the positive shares ``(p + 1) / (p + n + 2)``;
2. **pipeline** (skl2onnx, float64 input): the scaler and the logistic regression with
   ``raw_scores``, whose column 1 is ``decision_function`` (the logit of slip).

The score is that logit, float32, shape ``(batch,)``; slip (class ``"1"``) where it is
``>= 0``, i.e. where the estimator's probability is ``>= 1/2`` (``frames``' rule).

The runtime op ``davis_areas`` is not used: with no morphology it gives the areas, but
not the counts, and a preprocessing step replaces the graph's input, so the graph would
lose the frame it needs for the counts; two reductions in the graph cost less than the
op's Python loop.

:class:`EventFrameScores` is the estimator side of the parity check: it wraps the
fitted classifier and scores runtime event frames with the classifier's own pipeline on
features computed in numpy from the frames. The DAVIS deployer checks those features
equal the classifier's own (:meth:`EventFrameClassifier.frame_features` on the events)
on every held-out frame, so graph == wrapper == training-side estimator.
"""

from __future__ import annotations

import numpy as np
import onnx
from numpy.typing import ArrayLike, NDArray
from onnx import compose, helper
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.registry import (
    DEFAULT_OPSET,
    IR_VERSION,
    ExportedGraph,
    ExportError,
    check_opset,
    finalize_model,
    producers,
    register_exporter,
)
from slipkit.families.davis.classifier import (
    FEATURES,
    EventFrameClassifier,
    event_features,
)

#: Graph input: one event frame as counts per pixel (positive, negative).
INPUT = "event_frame"
SCORE = "score"
_FEATURES = "event_features"


def frame_counts(
    frames: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Event counts and areas (px) per polarity of event frames ``(n, 2, H, W)``.

    Returns
    -------
    counts, areas : ndarray of shape (n, 2)
        Events per polarity, and the pixels with at least one event.
    """
    f = np.asarray(frames, dtype=np.float64)
    if f.ndim != 4 or f.shape[1] != 2:
        raise ExportError(
            f"event frames must have shape (n, 2, height, width); got {f.shape}"
        )
    return f.sum(axis=(2, 3)), np.count_nonzero(f > 0, axis=(2, 3)).astype(np.float64)


class EventFrameScores(ClassifierMixin, BaseEstimator):
    """A fitted :class:`EventFrameClassifier` scoring the runtime's event frames.

    Parameters
    ----------
    classifier : EventFrameClassifier
        Fitted.

    Attributes
    ----------
    classes_ : ndarray
        ``[0, 1]`` (1 = slip).
    """

    def __init__(self, *, classifier: EventFrameClassifier) -> None:
        self.classifier = classifier

    def fit(
        self, X: ArrayLike | None = None, y: ArrayLike | None = None
    ) -> EventFrameScores:
        """Check the classifier is fitted (no data used)."""
        del X, y
        check_is_fitted(self.classifier, "pipeline_")
        self.classes_ = np.array([0, 1])
        return self

    def features(self, frames: ArrayLike) -> NDArray[np.float64]:
        """:data:`~slipkit.families.davis.classifier.FEATURES` of event frames ``(n, 2, H, W)``."""
        counts, areas = frame_counts(frames)
        return event_features(counts, areas)

    def decision_function(self, frames: ArrayLike) -> NDArray[np.float64]:
        """The logistic regression's logit of slip per frame: ``>= 0`` is slip."""
        check_is_fitted(self, "classes_")
        F = self.features(frames)
        return np.asarray(
            self.classifier.pipeline_.decision_function(F), dtype=np.float64
        )

    def predict(self, frames: ArrayLike) -> NDArray[np.int_]:
        """1 (slip) where the logit is ``>= 0`` (probability ``>= 1/2``), else 0."""
        return (self.decision_function(frames) >= 0).astype(int)


def _feature_graph(h: int, w: int, opset: int) -> onnx.ModelProto:
    """Frames ``(batch, 2, h, w)`` float32 -> the six features ``(batch, 6)`` float64."""
    g = GraphBuilder("event_frame_features", opset)
    axes = g.const([2, 3], np.int64, stem="pixel_axes")
    counts = g.op("ReduceSum", INPUT, axes, keepdims=0, stem="counts")  # (b, 2)
    fired = g.op("Cast", g.op("Greater", INPUT, g.const(0.0)), to=FLOAT)
    areas = g.op("ReduceSum", fired, axes, keepdims=0, stem="areas")  # (b, 2)
    one = g.const(1.0, np.float64)
    parts = []
    for name, v in (("counts", counts), ("areas", areas)):
        d = g.op("Cast", v, to=DOUBLE, stem=f"{name}64")
        parts.append((d, g.op("Log", g.op("Add", d, one), stem=f"log_{name}")))
    shares = []
    for d, _ in parts:
        pos = g.op("Slice", d, *(g.const([i], np.int64) for i in (0, 1, 1)))
        total = g.op("ReduceSum", d, g.const([1], np.int64), keepdims=1)
        shares.append(
            g.op(
                "Div",
                g.op("Add", pos, one),
                g.op("Add", total, g.const(2.0, np.float64)),
                stem="share",
            )
        )
    g.nodes.append(
        helper.make_node(
            "Concat", [parts[0][1], parts[1][1], *shares], [_FEATURES], axis=1
        )
    )
    return g.build(
        [helper.make_tensor_value_info(INPUT, FLOAT, ["batch", 2, h, w])],
        [helper.make_tensor_value_info(_FEATURES, DOUBLE, ["batch", len(FEATURES)])],
        doc="DAVIS event frame -> log1p counts, log1p areas, positive shares",
    )


def _pipeline_graph(estimator: EventFrameClassifier, opset: int) -> onnx.ModelProto:
    """skl2onnx's scaler + logistic regression on float64 features; output ``score``."""
    from skl2onnx import to_onnx
    from skl2onnx.common.data_types import DoubleTensorType

    pipe = estimator.pipeline_
    final = pipe.steps[-1][1]
    model = to_onnx(
        pipe,
        initial_types=[(_FEATURES, DoubleTensorType([None, len(FEATURES)]))],
        target_opset={"": opset, "ai.onnx.ml": 3},
        # raw_scores: the "probabilities" output holds [-logit, logit] (binary)
        options={id(final): {"zipmap": False, "raw_scores": True}},
    )
    graph = model.graph
    raw = graph.output[1].name
    graph.initializer.extend(
        [
            helper.make_tensor("slip_column", onnx.TensorProto.INT64, [], [1]),
        ]
    )
    graph.node.extend(
        [
            helper.make_node("Gather", [raw, "slip_column"], ["logit64"], axis=1),
            helper.make_node("Cast", ["logit64"], [SCORE], to=FLOAT),
        ]
    )
    del graph.output[:]
    graph.output.append(helper.make_tensor_value_info(SCORE, FLOAT, ["batch"]))
    model.ir_version = IR_VERSION
    return model


def export_event_classifier(
    estimator: EventFrameClassifier, *, opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Export a fitted :class:`EventFrameClassifier` over one event frame.

    Parameters
    ----------
    estimator : EventFrameClassifier
        Fitted (``pipeline_``).
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Input ``"event_frame"`` ``(batch, 2, height_px, width_px)`` float32 (positive,
        negative event counts per pixel of one ``frame_s`` frame), output ``"score"``
        ``(batch,)``: the logistic regression's logit of slip; class ``"1"`` where it
        is ``>= 0``.
    """
    import skl2onnx
    import sklearn

    if not isinstance(estimator, EventFrameClassifier):
        raise ExportError(
            f"export_event_classifier needs an EventFrameClassifier; got "
            f"{type(estimator).__name__}"
        )
    check_is_fitted(estimator, "pipeline_")
    opset = check_opset(opset)
    h, w = int(estimator.height_px), int(estimator.width_px)
    model = compose.merge_models(
        _feature_graph(h, w, opset),
        _pipeline_graph(estimator, opset),
        io_map=[(_FEATURES, _FEATURES)],
    )
    model.graph.name = "event_frame_classifier"
    model = finalize_model(model)
    return ExportedGraph(
        model=model,
        input_name=INPUT,
        input_shape=("batch", 2, h, w),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning=(
            "EventFrameClassifier: logistic-regression logit of slip for one event "
            "frame; slip ('1') where score >= 0 (probability >= 1/2)"
        ),
        score_method="decision_function",
        opset=opset,
        classes=("0", "1"),
        threshold=0.0,
        input_meaning=(
            f"one {float(estimator.frame_s) * 1e3:g} ms event frame: positive then "
            f"negative event counts per pixel, {h} x {w} px"
        ),
        producers=producers(
            **{"scikit-learn": sklearn.__version__, "skl2onnx": skl2onnx.__version__}
        ),
        strict=False,
    )


def export_event_scores(
    scores: EventFrameScores, *, opset: int = DEFAULT_OPSET
) -> ExportedGraph:
    """Export :class:`EventFrameScores`: its classifier's graph."""
    check_is_fitted(scores, "classes_")
    return export_event_classifier(scores.classifier, opset=opset)


register_exporter(EventFrameClassifier, export_event_classifier)
register_exporter(EventFrameScores, export_event_scores)

__all__ = [
    "EventFrameScores",
    "export_event_classifier",
    "export_event_scores",
    "frame_counts",
]
