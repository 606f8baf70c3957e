"""TacTip pin-velocity features as ONNX ops, so the gripper PC feeds raw pin positions.

The graph reproduces :func:`slipkit.features.pins.velocity_features` of the
difference of two consecutive camera frames. Its input has shape
``(batch, 2, 2 N)``: row 0 the previous frame, row 1 the current one, each laid
out as the ``pins`` stream, ``x0 .. x{N-1}, y0 .. y{N-1}`` (mm, NaN for a pin
not detected). The output is the feature vector of the velocity frame between
them (``dr`` in mm/frame, ``dtheta`` in rad, optional missing count), float32.

How the numpy rules map to ops
------------------------------
The graph has 25 nodes for the default features (shifted ``dr_dtheta``):
with 127 pins every node is a few hundred floats, so its cost is onnxruntime's
dispatch per node (~0.2-0.6 us), and the graph is written for few nodes rather
than few flops (``docs/export.md``, "Speed").

* Velocities: one float64 ``MatMul`` of ``[-1, 1]`` with the two frames (``cur -
  prev`` rounded once, as numpy's float64 difference), reshaped to ``(batch, 2,
  N)``: rows dx and dy, so later reductions over x and y are single nodes.
* Missing pins: ``dx^2 + dy^2`` (``ReduceSumSquare``) is NaN or inf exactly when
  dx or dy is (float32 differences square to at most ~5e77 in float64), so
  ``sq < inf`` is numpy's "both finite"; a pin missing in x or y gets ``dx = dy =
  0``, hence ``dr = 0``, no angle and nothing added to the mean.
* ``dr = ReduceL2(dx, dy)`` in float64: differences of float32 positions are at
  least 1.4e-45 mm when non-zero, so the squares never underflow and ``dr > 0``
  is exactly numpy's ``hypot(dx, dy) > 0`` (the has-angle mask).
* The circular mean: ``sum sin(theta_i) = sum dy_i / dr_i`` and ``sum cos = sum
  dx_i / dr_i`` over pins with an angle: ``LpNormalization`` gives the unit
  velocities (a still or missing pin stays at 0), one ``MatMul`` with a column of
  ``1 / RESULTANT_EPS`` their sum ``(C, S) / RESULTANT_EPS``. The count is
  ``sum |u_i|^2`` (exact to ~1e-16 relative, below the rounding of ``hypot(C,
  S)`` itself), so numpy's rule ``hypot(S, C) / count >``
  :data:`~slipkit.features.pins.RESULTANT_EPS` is ``hypot > count``; otherwise
  the mean is 0 rad, i.e. ``(C, S) := (1, 0)``, as numpy.
* The shifted angle ``wrap(theta_i - mean)`` is the angle from the mean direction
  ``m = (C, S)`` to the unit velocity ``u_i``: ``atan2(cross(m, u_i), dot(m,
  u_i))``, already in ``[-pi, pi]`` (no separate wrap; ``m`` needs no unit
  length). Both come from one ``MatMul`` of a per-frame matrix built from ``(C,
  S)`` (rows ``(C, S)`` and ``(-S, C)``) with the ``(batch, 2, N)`` unit
  velocities.
* ONNX has no Atan2. The graph uses ``atan2(y, x) = +-pi/2 - atan(x / y)``
  (``+pi/2`` for ``y >= 0``), which holds in every quadrant without a branch on
  ``x``; for ``y = 0`` the quotient is ``+-inf`` and the result 0 or ``+-pi``.
  Shifted angles take the half-plane term from the same ``Div`` and ``Atan`` as
  ``atan(y' / 1e-300)``, exactly ``+-pi/2`` in float32, with ``x' = x + 1e-280``
  and ``y' = y + 1e-290`` (the ``MatMul`` gives ``y`` twice, one row per term):
  a zero ``y`` becomes positive, so an exact ``-pi`` maps to ``+pi`` like
  :func:`~slipkit.features.pins.wrap_angle`, and a pin without an angle (``x = y
  = 0``) gets ``pi/2 - atan(1e10) = 0`` rad, the module's "no direction",
  without a mask. For every other pin ``|(x, y)| = |m| >= 1``, and a non-zero
  ``x`` or ``y`` is at least ~1e-170 (unit-vector components of float32
  differences, and their sums, are at least ~1e-90 when non-zero), so the
  offsets move no angle and never flip the sign of ``y``. A final float32
  ``MatMul`` with ``[-1, 1]`` subtracts the two terms (one rounding, like ``Sub``).
* Unshifted angles keep numpy's sign-of-zero rule (``atan2(-0.0, -1) = -pi``):
  the half-plane comes from ``1 / dy > 0``, ``(1e-300, -0.0)`` is added to
  ``(dx, dy)`` (a non-zero dx is at least 1.4e-45 mm), and the rows are
  subtracted with ``Sub`` and masked with the zero in ``Where``'s *second*
  branch, the two places where onnxruntime would otherwise turn ``-0.0`` into
  ``+0.0``.

Everything before ``Atan`` runs in float64 (for the mean of nearly cancelling
unit vectors float32 would turn rounding noise into a direction); ``Atan``, which
onnxruntime 1.31 implements for float32 only, takes the float64 quotient rounded
once: about 1e-7 rad of error. Pins moving exactly against the frame's mean
direction sit on the ``+-pi`` branch cut, where rounding can put the graph and
numpy on opposite sides (a 2 pi difference); compare such angles circularly.
"""

from __future__ import annotations

import math

import numpy as np
from onnx import helper

from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.registry import (
    DEFAULT_OPSET,
    ExportedGraph,
    ExportError,
    producers,
)
from slipkit.features.pins import RESULTANT_EPS, VARIANTS, feature_names

#: Name of the raw-pin input of every graph with the features inside.
PINS_INPUT = "pins"


def feature_spec(
    n_pins: int, variant: str, shift_angles: bool, missing_count: bool
) -> dict[str, object]:
    """The ``features`` entry of an :class:`ExportedGraph` with these features inside."""
    return {
        "kind": "tactip_pin_velocity",
        "n_pins": int(n_pins),
        "variant": variant,
        "shift_angles": bool(shift_angles),
        "missing_count": bool(missing_count),
        "input_layout": "(batch, 2, 2N): [previous, current] frame of x0..x{N-1}, y0..y{N-1} (mm)",
        "names": list(feature_names(n_pins, variant, missing_count=missing_count)),  # type: ignore[arg-type]
    }


def n_features_of(n_pins: int, variant: str, missing_count: bool) -> int:
    """Length of the feature vector for ``n_pins`` pins."""
    return (2 if variant == "dr_dtheta" else 1) * n_pins + int(missing_count)


def pins_from_features(n_features: int, variant: str, missing_count: bool) -> int:
    """The pin count ``N`` that gives ``n_features`` features, or ExportError."""
    per_pin = 2 if variant == "dr_dtheta" else 1
    body = n_features - int(missing_count)
    if body < per_pin or body % per_pin:
        raise ExportError(
            f"{n_features} features do not fit variant={variant!r}, "
            f"missing_count={missing_count} (expected {per_pin} N"
            f"{' + 1' if missing_count else ''})"
        )
    return body // per_pin


def _reduce(
    g: GraphBuilder, op: str, x: str, axes: list[int], *, keepdims: int = 1
) -> str:
    """A Reduce* node over ``axes``: an input from opset 18 on (13 for ReduceSum), else an attribute."""
    if op == "ReduceSum" or g.opset >= 18:
        return g.op(op, x, g.const(axes, np.int64), keepdims=keepdims)
    return g.op(op, x, axes=axes, keepdims=keepdims)


def _split_rows(g: GraphBuilder, x: str, rows: int = 1) -> tuple[str, str]:
    """Split ``(batch, 2 rows, N)`` into two ``(batch, rows, N)`` halves (one node)."""
    first, second = f"{x}_half0", f"{x}_half1"
    g.nodes.append(
        helper.make_node(
            "Split", [x, g.const([rows, rows], np.int64)], [first, second], axis=1
        )
    )
    return first, second


def _angle(g: GraphBuilder, x: str, y: str, upper: str) -> str:
    """``atan2(y, x)`` in float32 as ``+-pi/2 - atan(x / y)``, the sign taken from ``upper``.

    For ``y != 0`` this is atan2 in every quadrant with no branch on ``x``; for a
    zero ``y`` the division gives ``+-inf``, ``atan`` ``+-pi/2``, so the result is
    0 or ``+-pi`` by the sign of ``x`` and the half-plane ``upper`` (bool, True for
    ``+pi/2``). ``x = y = 0`` gives NaN (callers keep it out). The quotient is taken
    in float64 and rounded once for ``Atan``, which onnxruntime has in float32 only.
    """
    ratio = g.op("Cast", g.op("Div", x, y), to=FLOAT)
    half = g.op(
        "Where",
        upper,
        g.const(math.pi / 2.0, np.float32),
        g.const(-math.pi / 2.0, np.float32),
    )
    return g.op("Sub", half, g.op("Atan", ratio))


def velocity_feature_nodes(
    g: GraphBuilder,
    pins: str,
    n_pins: int,
    *,
    variant: str = "dr_dtheta",
    shift_angles: bool = True,
    missing_count: bool = False,
) -> str:
    """Append the feature computation to ``g``; returns the float32 ``(batch, F)`` output."""
    if variant not in VARIANTS:
        raise ExportError(f"variant must be one of {VARIANTS}; got {variant!r}")
    if n_pins < 1:
        raise ExportError(f"n_pins must be >= 1; got {n_pins}")
    n = n_pins
    angles = variant in ("dr_dtheta", "dtheta")
    raw_angles = angles and not shift_angles
    p = g.op("Cast", pins, to=DOUBLE)  # (batch, 2, 2N)
    if raw_angles:
        # Raw atan2 keeps numpy's sign of a zero dy, and MatMul's zero-initialised
        # accumulator turns -0.0 - 0.0 into +0.0: subtract the rows as numpy does.
        prev, cur = _split_rows(g, p)
        v = g.op("Sub", cur, prev)
    else:
        v = g.op("MatMul", g.const([[-1.0, 1.0]], np.float64), p)  # cur - prev
    v = g.op("Reshape", v, g.const([-1, 2, n], np.int64))  # (batch, 2, N): dx; dy
    # dx^2 + dy^2 is NaN or inf exactly when dx or dy is (float32 differences
    # square to at most ~5e77 in float64, so a finite pin never overflows).
    sq = _reduce(g, "ReduceSumSquare", v, [1])  # (batch, 1, N)
    zero = g.const(0.0, np.float64)
    if raw_angles:
        # onnxruntime's Where passes -0.0 through from its third input but returns
        # +0.0 from its second, and a zero dy must keep its sign here. The mask is
        # IsNaN(sq - sq) rather than Not(sq < inf): the graph optimiser rewrites
        # Where(Not(c), a, b) as Where(c, b, a), which would lose the sign again.
        missing = g.op("IsNaN", g.op("Sub", sq, sq))
        v = g.op("Where", missing, zero, v)
    else:
        finite = g.op("Less", sq, g.const(math.inf, np.float64))
        v = g.op("Where", finite, v, zero)
    parts: list[str] = []
    if variant in ("dr_dtheta", "dr"):
        parts.append(g.op("Cast", _reduce(g, "ReduceL2", v, [1]), to=FLOAT))
    if angles:
        if shift_angles:
            # Unit velocities; LpNormalization leaves a zero column (still or missing
            # pin, no angle) at 0, so it adds nothing to C, S or the count.
            u = g.op("LpNormalization", v, axis=1, p=2)
            # (C, S) / RESULTANT_EPS as one MatMul: the rule hypot(C, S) / count >
            # RESULTANT_EPS becomes hypot > count, and the scale leaves the mean
            # direction alone.
            cs = g.op(
                "MatMul", u, g.const(np.full((n, 1), 1.0 / RESULTANT_EPS), np.float64)
            )
            resultant = _reduce(g, "ReduceL2", cs, [1])  # (batch, 1, 1)
            # sum |u_i|^2 = count to ~1e-16 relative: below the rounding of
            # hypot(C, S) itself, so the RESULTANT_EPS rule is unchanged.
            count = _reduce(g, "ReduceSumSquare", u, [1, 2])
            directed = g.op("Greater", resultant, count)
            m = g.op("Where", directed, cs, g.const([[1.0], [0.0]], np.float64))
            # One MatMul of [[C, S], [-S, C], [-S, C], [0, 0]] with u gives the rows
            # x = dot(m, u_i), y = cross(m, u_i), y again, and 0. Rows 1 and 2 are the
            # same products of the same numbers, so both terms below see one y.
            rows = g.op(
                "MatMul",
                g.const(
                    [[1, 0], [0, 1], [0, -1], [1, 0], [0, -1], [1, 0], [0, 0], [0, 0]],
                    np.float64,
                ),
                m,
            )
            rows = g.op("Reshape", rows, g.const([-1, 4, 2], np.int64))
            rows = g.op("MatMul", rows, u)  # (batch, 4, N)
            # atan2(y, x) = atan(y' / 1e-300) - atan(x' / y'), both halves from one
            # Div and one Atan, with x' = x + 1e-280 and y' = y + 1e-290 (see the
            # module notes): the first term is exactly +-pi/2 by the sign of y'.
            rows = g.op(
                "Add",
                rows,
                g.const([[1e-280], [1e-290], [1e-290], [1e-300]], np.float64),
            )
            num, den = _split_rows(g, rows, 2)
            atans = g.op("Atan", g.op("Cast", g.op("Div", num, den), to=FLOAT))
            # -atan(x' / y') + atan(y' / 1e-300), rounded once like Sub.
            theta = g.op("MatMul", g.const([[-1.0, 1.0]], np.float32), atans)
        else:
            # + (1e-300, -0.0): a still or missing pin (0, 0) gets atan2(+-0, 1e-300)
            # = 0 rad instead of NaN; a non-zero dx is at least 1.4e-45 mm (a float32
            # difference), so no other angle moves, and adding -0.0 keeps dy's sign.
            v_safe = g.op("Add", v, g.const([[1e-300], [-0.0]], np.float64))
            dx, dy = _split_rows(g, v_safe)
            # 1 / -0.0 = -inf: the sign bit of a zero dy picks the half-plane, as numpy.
            upper = g.op(
                "Greater",
                g.op("Div", g.const(1.0, np.float64), dy),
                g.const(0.0, np.float64),
            )
            theta = _angle(g, dx, dy, upper)
        parts.append(theta)
    if missing_count:
        one32, zero32 = g.const(1.0, np.float32), g.const(0.0, np.float32)
        gone = (
            g.op("Where", missing, one32, zero32)
            if raw_angles
            else g.op("Where", finite, zero32, one32)
        )
        parts.append(_reduce(g, "ReduceSum", gone, [2]))  # (batch, 1, 1)
    feats = parts[0] if len(parts) == 1 else g.op("Concat", *parts, axis=2)
    f = n_features_of(n_pins, variant, missing_count)
    return g.op("Reshape", feats, g.const([-1, f], np.int64), stem="features")


def export_velocity_features(
    n_pins: int,
    *,
    variant: str = "dr_dtheta",
    shift_angles: bool = True,
    missing_count: bool = False,
    opset: int = DEFAULT_OPSET,
) -> ExportedGraph:
    """A graph of the pin-velocity features alone: ``(batch, 2, 2N)`` pins -> ``(batch, F)``.

    Parameters
    ----------
    n_pins : int
        Pins per frame, N.
    variant, shift_angles, missing_count
        As :func:`slipkit.features.pins.velocity_features`.
    opset : int
        Default-domain opset (17 or 18).

    Returns
    -------
    ExportedGraph
        Input ``"pins"`` (float32, mm), output ``"features"`` (float32, mm/frame and rad).
    """
    g = GraphBuilder("tactip_velocity_features", opset)
    out = velocity_feature_nodes(
        g,
        PINS_INPUT,
        n_pins,
        variant=variant,
        shift_angles=shift_angles,
        missing_count=missing_count,
    )
    g.rename(out, "features")
    f = n_features_of(n_pins, variant, missing_count)
    model = g.build(
        [helper.make_tensor_value_info(PINS_INPUT, FLOAT, ["batch", 2, 2 * n_pins])],
        [helper.make_tensor_value_info("features", FLOAT, ["batch", f])],
        doc="slipkit.features.pins.velocity_features of two consecutive pin frames",
    )
    return ExportedGraph(
        model=model,
        input_name=PINS_INPUT,
        input_shape=("batch", 2, 2 * n_pins),
        output_names=("features",),
        score_output="features",
        score_meaning=f"pin-velocity features {variant} (dr mm/frame, dtheta rad)",
        score_method="transform",
        opset=g.opset,
        input_meaning="previous and current frame of x0..x{N-1}, y0..y{N-1} (mm, NaN: pin not detected)",
        features=feature_spec(n_pins, variant, shift_angles, missing_count),
        producers=producers(),
    )
