"""Exporters for the pin-count-independent TacTip estimators.

* :class:`~slipkit.families.tactip.detector.PinMotionDetector` as a
  :class:`~slipkit.export.detectors.DetectorGraph`: a window of the last ``W = span +
  consecutive`` raw pin frames ``(batch, W, 2N)`` (mm, NaN for a pin not detected,
  oldest first) -> ``score`` ``(batch,)`` mm/frame, the batch detector's
  ``decision_function`` at the window's last frame.
* :func:`pooled_feature_nodes`: :func:`slipkit.features.pins.pooled_features` as
  ONNX ops on the per-pin ``dr_dtheta`` features, used by the
  :class:`~slipkit.models.svm.TacTipSVM` exporter for ``features="pooled"``.

The pin motion graph, in float64 after the input cast:

* NaN pins: the finite mask ``F`` and the frames with NaN set to 0 (``Where``); every
  mean displacement ``d(a, b)`` the detector needs is one row of a constant matrix
  (``-1`` at frame ``a``, ``+1`` at ``b``), so all of them are one ``MatMul``, and a
  pin counts in row ``(a, b)`` when ``F_a F_b`` is 1 for both x and y (two more
  ``MatMul`` with the row's one-hot selections, multiplied).
* Means over the counted pins, then ``|v|`` (coherent) or ``-(v . u) / max(|u|,
  MIN_REFERENCE_MM)`` (reversal); a frame with no counted pin scores ``-inf``; the
  minimum over the last ``consecutive`` frames is the score.

The graph is built for the pin count of the stream it is exported for (the input
shape is fixed); the detector itself scores any count, so export it again for a
sensor with another layout.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.utils.validation import check_is_fitted

from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.detectors import DetectorGraph, _finish, _graph, _prologue
from slipkit.export.registry import DEFAULT_OPSET, ExportError, register_exporter
from slipkit.families.tactip.detector import MIN_REFERENCE_MM, PinMotionDetector
from slipkit.features.pins import POOLED_NAMES


def _reduce(g: GraphBuilder, op: str, x: str, axes: list[int], keepdims: int) -> str:
    """A Reduce* node: axes as an input (ReduceSum, or opset >= 18) or an attribute."""
    if op == "ReduceSum" or g.opset >= 18:
        return g.op(op, x, g.const(axes, np.int64), keepdims=keepdims)
    return g.op(op, x, axes=axes, keepdims=keepdims)


def _pairs(detector: PinMotionDetector) -> list[tuple[int, int]]:
    """(from, to) frame pairs within the window: the c velocities, then the c references."""
    w, c = detector.window, int(detector.consecutive)
    last = range(w - c, w)
    pairs = [(t - 1, t) for t in last]
    if detector.score == "reversal":
        g, lb = int(detector.gap), int(detector.lookback)
        pairs += [(t - g - lb, t - g) for t in last]
    return pairs


def export_pin_motion(
    detector: PinMotionDetector,
    *,
    n_pins: int | None = None,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`PinMotionDetector` for ``n_pins`` pins per frame.

    Parameters
    ----------
    detector : PinMotionDetector
        Fitted.
    n_pins : int, optional
        Pins per frame of the stream the graph will read (default: the pins seen in
        ``fit``).
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    DetectorGraph
        Input ``(batch, window, 2 n_pins)`` raw pin frames (mm), oldest first; output
        ``score`` (mm/frame); hop 1; decisions from frame ``window - 1`` on.
    """
    check_is_fitted(detector, "threshold_")
    n = int(detector.n_pins_in_ if n_pins is None else n_pins)
    if n < 1:
        raise ExportError(f"n_pins must be >= 1; got {n}")
    w, c = detector.window, int(detector.consecutive)
    pairs = _pairs(detector)
    m = len(pairs)
    diff = np.zeros((m, w))
    sel_a, sel_b = np.zeros((m, w)), np.zeros((m, w))
    for i, (a, b) in enumerate(pairs):
        diff[i, a], diff[i, b] = -1.0, 1.0
        sel_a[i, a], sel_b[i, b] = 1.0, 1.0
    g = GraphBuilder("tactip_pin_motion", opset)
    inp, x = _prologue(g, w, 2 * n)
    zero = g.const(0.0, np.float64)
    finite = g.op("Not", g.op("IsNaN", g.op("Sub", x, x)), stem="finite")
    x0 = g.op("Where", finite, x, zero, stem="x0")
    f = g.op("Cast", finite, to=DOUBLE)
    d = g.op("MatMul", g.const(diff, np.float64), x0, stem="disp")  # (batch, m, 2N)
    ok = g.op(
        "Mul",
        g.op("MatMul", g.const(sel_a, np.float64), f),
        g.op("MatMul", g.const(sel_b, np.float64), f),
    )
    shape4 = g.const([-1, m, 2, n], np.int64)
    d4 = g.op("Reshape", d, shape4)
    ok4 = g.op("Reshape", ok, shape4)
    ok_xy = _reduce(g, "ReduceMin", ok4, [2], 1)  # (batch, m, 1, N): x and y finite
    count = _reduce(g, "ReduceSum", ok_xy, [2, 3], 0)  # (batch, m)
    sums = _reduce(g, "ReduceSum", g.op("Mul", d4, ok_xy), [3], 0)  # (batch, m, 2)
    means = g.op(
        "Div",
        sums,
        g.op(
            "Unsqueeze",
            g.op("Max", count, g.const(1.0, np.float64)),
            g.const([2], np.int64),
        ),
    )
    if detector.score == "reversal":
        v = g.op(
            "Slice",
            means,
            g.const([0], np.int64),
            g.const([c], np.int64),
            g.const([1], np.int64),
        )
        u = g.op(
            "Slice",
            means,
            g.const([c], np.int64),
            g.const([2 * c], np.int64),
            g.const([1], np.int64),
        )
        dot = _reduce(g, "ReduceSum", g.op("Mul", v, u), [2], 0)
        norm = g.op("Sqrt", _reduce(g, "ReduceSum", g.op("Mul", u, u), [2], 0))
        raw = g.op(
            "Div",
            g.op("Neg", dot),
            g.op("Max", norm, g.const(MIN_REFERENCE_MM, np.float64)),
        )
        count_v = g.op(
            "Slice",
            count,
            g.const([0], np.int64),
            g.const([c], np.int64),
            g.const([1], np.int64),
        )
    else:
        raw = g.op("Sqrt", _reduce(g, "ReduceSum", g.op("Mul", means, means), [2], 0))
        count_v = count
    raw = g.op(
        "Where",
        g.op("Greater", count_v, zero),
        raw,
        g.const(-np.inf, np.float64),
    )
    score64 = _reduce(g, "ReduceMin", raw, [1], 0)
    model = _finish(
        g, inp, score64, f"PinMotionDetector ({detector.score}) over {w} pin frames"
    )
    return _graph(
        detector,
        model,
        opset=g.opset,
        window=w,
        channels=2 * n,
        hop=1,
        first_decision=w - 1,
        score_meaning=(
            f"PinMotionDetector.decision_function ({detector.score}, mm/frame) at the "
            f"window's last frame: the minimum over the last {c} frames; the lowest "
            "float32 where no pin is present; slip ('1') where score >= threshold"
        ),
        input_meaning=(
            f"the last {w} frames of x0..x{n - 1}, y0..y{n - 1} (mm, NaN: pin not "
            "detected), oldest first"
        ),
        features={
            "score": detector.score,
            "lookback": int(detector.lookback),
            "gap": int(detector.gap),
            "consecutive": c,
            "n_pins": n,
        },
    )


def pooled_feature_nodes(g: GraphBuilder, feats: str, n_pins: int) -> str:
    """Append :func:`slipkit.features.pins.pooled_features` of ``(batch, 2N)`` float32
    ``dr_dtheta`` features; returns the float32 ``(batch, 6)`` output."""
    n = int(n_pins)
    f = g.op("Reshape", g.op("Cast", feats, to=DOUBLE), g.const([-1, 2, n], np.int64))
    one = g.const([1], np.int64)
    dr = g.op("Slice", f, g.const([0], np.int64), one, one)  # (batch, 1, N)
    theta = g.op("Slice", f, one, g.const([2], np.int64), one)
    zero = g.const(0.0, np.float64)
    present = g.op("Greater", dr, zero)
    p = g.op("Cast", present, to=DOUBLE)
    count = g.op("Max", _reduce(g, "ReduceSum", p, [2], 0), g.const(1.0, np.float64))
    drp = g.op("Where", present, dr, zero)
    # ONNX Cos / Sin have no float64 kernel in onnxruntime 1.31: angles in float32
    # (about 1e-7 relative, as the in-graph angles themselves).
    t32 = g.op("Cast", theta, to=FLOAT)
    cos = g.op("Mul", g.op("Cast", g.op("Cos", t32), to=DOUBLE), p)
    sin = g.op("Mul", g.op("Cast", g.op("Sin", t32), to=DOUBLE), p)

    def total(v: str) -> str:
        return _reduce(g, "ReduceSum", v, [2], 0)  # (batch, 1)

    speed_mean = g.op("Div", total(drp), count)
    speed_rms = g.op("Sqrt", g.op("Div", total(g.op("Mul", drp, drp)), count))
    speed_max = _reduce(g, "ReduceMax", drp, [2], 0)
    c_sum, s_sum = total(cos), total(sin)
    resultant = g.op(
        "Div",
        g.op("Sqrt", g.op("Add", g.op("Mul", c_sum, c_sum), g.op("Mul", s_sum, s_sum))),
        count,
    )
    vc, vs = total(g.op("Mul", drp, cos)), total(g.op("Mul", drp, sin))
    velocity = g.op(
        "Div",
        g.op("Sqrt", g.op("Add", g.op("Mul", vc, vc), g.op("Mul", vs, vs))),
        count,
    )
    alignment = g.op("Mul", speed_mean, resultant)
    cols = [speed_mean, speed_rms, speed_max, resultant, velocity, alignment]
    assert len(cols) == len(POOLED_NAMES)
    out = g.op("Concat", *cols, axis=1)
    return g.op("Cast", out, to=FLOAT, stem="pooled")


def pooled_spec(n_pins: int) -> dict[str, Any]:
    """The ``features`` entry's pooled part (names, the pin count the graph reads)."""
    return {"pooled": list(POOLED_NAMES), "pooled_from_pins": int(n_pins)}


register_exporter(PinMotionDetector, export_pin_motion)

__all__ = ["export_pin_motion", "pooled_feature_nodes", "pooled_spec"]
