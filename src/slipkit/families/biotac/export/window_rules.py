"""Exporters of the analytic window classifiers: a flattened electrode window in, the score out.

Both classifiers score a window of the window-classification task
(:class:`~slipkit.train.tasks.slip_type.WindowClassification`) with a closed formula and
one threshold chosen on the training ROC, so each graph is that formula in ONNX ops:

* :class:`~slipkit.families.biotac.electrode_energy.ElectrodeEnergyClassifier` (``dos_real``'s
  ``energy``): the RMS frame-to-frame change over all channels, NaN steps skipped
  (``nanmean``), a non-finite energy read as 0, minus ``threshold_`` (counts / frame);
* :class:`~slipkit.families.biotac.slip_twist.SlipTwistClassifier` (``biotac_slip_type``'s
  ``twist``): per electrode the mean of the last ``k`` frames minus the mean of the
  first ``k`` (``k = max(1, width // 4)``, NaN frames skipped, a non-finite change read
  as 0), the share that cancels out ``1 - |sum D| / sum |D|`` (0 without change), minus
  ``threshold_`` (dimensionless).

Input: ``window`` ``(batch, width * n_channels)`` float32, one window per row,
frame-major (:func:`slipkit.features.windows.sliding_windows`, the rows the classifier
was fitted on; the deployer's window is the runtime ring buffer flattened in the same
order). Output: ``score`` ``(batch,)`` float32, the classifier's ``decision_function``.
Inside, the graph casts the window to float64 as the batch form computes, so the only
rounding the batch lacks is the float32 input.

Decision: a threshold rule ``classes[1]`` where ``score >= 0`` (``strict=False``, as
both ``predict`` methods). For the twist rule ``classes`` are ``(linear_class_,
rotational_class)``; for the energy rule ``(touch_class, motion_class_)``: a
direction-blind rule predicts only these two of its seven classes, so its bundle is a
binary motion-vs-touch detector whose slip class is the motion class
(registered with :func:`slipkit.export.deploy.register_window_rule`, read by the window
deployer).

The classifiers keep no input width (they take any window of whole frames), so the
exporters need the window length in frames, ``n_frames``; the window deployer passes it
from the task (both rules registered as window rules). Hand-built graphs: the formulas are a few
reductions, and no converter library knows these classes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from onnx import helper
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.deploy import register_window_rule
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    ExportError,
    producers,
    register_exporter,
)
from slipkit.families.biotac.electrode_energy import ElectrodeEnergyClassifier
from slipkit.families.biotac.slip_twist import SlipTwistClassifier

WINDOW_INPUT = "window"
SCORE = "score"


def _check_width(name: str, n_frames: Any, min_frames: int) -> int:
    """``n_frames`` as an int >= ``min_frames``, else an ExportError naming the option."""
    if n_frames is None:
        raise ExportError(
            f"{name} export: n_frames (the window length in frames) is required: the "
            "classifier keeps no input width; slipkit export passes the task's window"
        )
    if isinstance(n_frames, bool) or int(n_frames) != n_frames or n_frames < min_frames:
        raise ExportError(
            f"{name} export: n_frames must be a whole number >= {min_frames}; got "
            f"{n_frames!r}"
        )
    return int(n_frames)


def _prologue(g: GraphBuilder, width: int, channels: int) -> tuple[Any, str]:
    """The flat float32 input and the window as float64 ``(batch, width, channels)``."""
    inp = helper.make_tensor_value_info(
        WINDOW_INPUT, FLOAT, ["batch", width * channels]
    )
    x64 = g.op("Cast", WINDOW_INPUT, to=DOUBLE, stem="x64")
    shape = g.const([-1, width, channels], np.int64, stem="shape")
    return inp, g.op("Reshape", x64, shape, stem="frames")


def _not_finite(g: GraphBuilder, v: str) -> str:
    # v - v is NaN exactly for NaN and +-inf (the trick slipkit.export.pins uses).
    return g.op("IsNaN", g.op("Sub", v, v), stem="not_finite")


def _nan_mean(g: GraphBuilder, v: str, axes: list[int]) -> str:
    """``numpy.nanmean`` over ``axes`` (keepdims 0): NaN skipped, NaN where all are."""
    nan = g.op("IsNaN", v, stem="isnan")
    zero = g.const(0.0, np.float64, stem="zero")
    kept = g.op("Where", nan, zero, v, stem="kept")
    count = g.op("Cast", g.op("Not", nan), to=DOUBLE, stem="count")
    ax = g.const(axes, np.int64, stem="axes")
    total = g.op("ReduceSum", kept, ax, keepdims=0, stem="sum")
    n = g.op("ReduceSum", count, ax, keepdims=0, stem="n")
    return g.op("Div", total, n, stem="nanmean")  # 0 / 0 = NaN, as numpy


def _finite_or_zero(g: GraphBuilder, v: str) -> str:
    """``numpy.where(numpy.isfinite(v), v, 0)``."""
    return g.op(
        "Where",
        _not_finite(g, v),
        g.const(0.0, np.float64, stem="zero"),
        v,
        stem="finite",
    )


def _finish(g: GraphBuilder, inp: Any, score64: str, doc: str) -> Any:
    g.nodes.append(helper.make_node("Cast", [score64], [SCORE], to=FLOAT))
    return g.build(
        [inp], [helper.make_tensor_value_info(SCORE, FLOAT, ["batch"])], doc=doc
    )


def _exported(
    model: Any,
    *,
    opset: int,
    width: int,
    channels: int,
    classes: tuple[str, str],
    meaning: str,
) -> ExportedGraph:
    return ExportedGraph(
        model=model,
        input_name=WINDOW_INPUT,
        input_shape=("batch", width * channels),
        output_names=(SCORE,),
        score_output=SCORE,
        score_meaning=meaning,
        score_method="decision_function",
        opset=opset,
        classes=classes,
        threshold=0.0,
        input_meaning=(
            f"a window of {width} frames x {channels} channels, flattened frame-major "
            "(oldest frame first)"
        ),
        features=None,
        producers=producers(),
        strict=False,
    )


def export_electrode_energy(
    classifier: ElectrodeEnergyClassifier,
    *,
    n_frames: int | None = None,
    opset: int = DEFAULT_OPSET,
) -> ExportedGraph:
    """Export a fitted :class:`ElectrodeEnergyClassifier` for windows of ``n_frames`` frames.

    Parameters
    ----------
    classifier : ElectrodeEnergyClassifier
        Fitted (``threshold_`` in counts / frame).
    n_frames : int
        Frames per window (>= 2: the energy is a frame-to-frame change).
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Input ``(batch, n_frames * n_channels)``; ``score`` = energy - threshold
        (counts / frame); classes ``(touch_class, motion_class_)``, motion where
        ``score >= 0``.
    """
    check_is_fitted(classifier, "threshold_")
    width = _check_width("ElectrodeEnergyClassifier", n_frames, 2)
    c = int(classifier.n_channels)
    g = GraphBuilder("electrode_energy", opset)
    inp, x = _prologue(g, width, c)
    hi = g.op(
        "Slice",
        x,
        g.const([1], np.int64),
        g.const([width], np.int64),
        g.const([1], np.int64),
    )
    lo = g.op(
        "Slice",
        x,
        g.const([0], np.int64),
        g.const([width - 1], np.int64),
        g.const([1], np.int64),
    )
    d = g.op("Sub", hi, lo, stem="step")
    d2 = g.op("Mul", d, d, stem="step2")  # (batch, width - 1, C)
    energy = _finite_or_zero(g, g.op("Sqrt", _nan_mean(g, d2, [1, 2]), stem="energy"))
    score = g.op(
        "Sub", energy, g.const(float(classifier.threshold_), np.float64), stem="s64"
    )
    model = _finish(g, inp, score, "ElectrodeEnergyClassifier: energy - threshold")
    return _exported(
        model,
        opset=g.opset,
        width=width,
        channels=c,
        classes=(str(classifier.touch_class), str(classifier.motion_class_)),
        meaning=(
            "ElectrodeEnergyClassifier.decision_function: RMS frame-to-frame change "
            f"(counts / frame) minus the threshold {float(classifier.threshold_):.6g}; "
            f"motion ({classifier.motion_class_!r}) where score >= 0, else touch "
            f"({classifier.touch_class!r})"
        ),
    )


def export_slip_twist(
    classifier: SlipTwistClassifier,
    *,
    n_frames: int | None = None,
    opset: int = DEFAULT_OPSET,
) -> ExportedGraph:
    """Export a fitted :class:`SlipTwistClassifier` for windows of ``n_frames`` frames.

    Parameters
    ----------
    classifier : SlipTwistClassifier
        Fitted (``threshold_`` is a twist share, dimensionless).
    n_frames : int
        Frames per window (>= 1).
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Input ``(batch, n_frames * n_channels)``; ``score`` = twist share - threshold;
        classes ``(linear_class_, rotational_class)``, rotational where ``score >= 0``.
    """
    check_is_fitted(classifier, "threshold_")
    width = _check_width("SlipTwistClassifier", n_frames, 1)
    c = int(classifier.n_channels)
    k = max(1, width // 4)
    g = GraphBuilder("slip_twist", opset)
    inp, x = _prologue(g, width, c)
    step = g.const([1], np.int64)
    axis = g.const([1], np.int64)
    first = g.op("Slice", x, g.const([0], np.int64), g.const([k], np.int64), axis, step)
    last = g.op(
        "Slice",
        x,
        g.const([width - k], np.int64),
        g.const([width], np.int64),
        axis,
        step,
    )
    D = _finite_or_zero(
        g,
        g.op("Sub", _nan_mean(g, last, [1]), _nan_mean(g, first, [1]), stem="change"),
    )  # (batch, C)
    chan = g.const([1], np.int64, stem="chan")
    total = g.op("ReduceSum", g.op("Abs", D), chan, keepdims=0, stem="total")
    net = g.op("Abs", g.op("ReduceSum", D, chan, keepdims=0), stem="net")
    zero = g.const(0.0, np.float64, stem="zero")
    moved = g.op("Greater", total, zero, stem="moved")
    safe = g.op("Where", moved, total, g.const(1.0, np.float64), stem="safe")
    share = g.op(
        "Sub", g.const(1.0, np.float64), g.op("Div", net, safe), stem="cancelled"
    )
    r = g.op("Where", moved, share, zero, stem="twist_share")
    score = g.op(
        "Sub", r, g.const(float(classifier.threshold_), np.float64), stem="s64"
    )
    model = _finish(g, inp, score, "SlipTwistClassifier: twist share - threshold")
    return _exported(
        model,
        opset=g.opset,
        width=width,
        channels=c,
        classes=(str(classifier.linear_class_), str(classifier.rotational_class)),
        meaning=(
            "SlipTwistClassifier.decision_function: share of the electrode change "
            f"that cancels out (0..1, k = {k} frames at each end) minus the threshold "
            f"{float(classifier.threshold_):.6g}; {classifier.rotational_class!r} "
            f"where score >= 0, else {classifier.linear_class_!r}"
        ),
    )


def _energy_slip_classes(model: ElectrodeEnergyClassifier) -> list[str]:
    """The energy rule's graph decides between touch and its one motion class
    (``motion_class_``): that class is the slip class."""
    return [str(model.motion_class_)]


register_exporter(ElectrodeEnergyClassifier, export_electrode_energy)
register_exporter(SlipTwistClassifier, export_slip_twist)
register_window_rule(ElectrodeEnergyClassifier, _energy_slip_classes)
register_window_rule(SlipTwistClassifier)

__all__ = [
    "export_electrode_energy",
    "export_slip_twist",
]
