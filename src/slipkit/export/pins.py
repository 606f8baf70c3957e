"""TacTip pin-velocity features as ONNX ops, so the gripper PC feeds raw pin positions.

The graph reproduces :func:`slipkit.features.pins.velocity_features` of the
difference of two consecutive camera frames. Its input has shape
``(batch, 2, 2 N)``: row 0 the previous frame, row 1 the current one, each laid
out as the ``pins`` stream, ``x0 .. x{N-1}, y0 .. y{N-1}`` (mm, NaN for a pin
not detected). The output is the feature vector of the velocity frame between
them (``dr`` in mm/frame, ``dtheta`` in rad, optional missing count), float32.

How the numpy rules map to ops
------------------------------
* Missing pins: ``isfinite(v)`` is ``IsNaN(v - v)`` (``inf - inf`` and ``NaN -
  NaN`` are NaN, a finite ``v - v`` is 0), one op for both coordinates; a pin
  missing in x or y gets ``dx = dy = 0``.
* ``dr = sqrt(dx^2 + dy^2)``, in float64: differences of float32 positions are
  at least 1.4e-45 mm when non-zero, so the squares never underflow and ``dr >
  0`` is exactly numpy's ``hypot(dx, dy) > 0`` (the has-angle mask).
* The circular mean: ``sum sin(theta_i) = sum dy_i / dr_i`` and ``sum cos = sum
  dx_i / dr_i`` over pins with an angle, so no per-pin angle is needed for it.
  A frame whose resultant ``hypot(S, C) / count`` is at most
  :data:`~slipkit.features.pins.RESULTANT_EPS` has mean 0 rad, i.e. ``(C, S) :=
  (1, 0)``, as numpy.
* The shifted angle ``wrap(theta_i - mean)`` is the angle from the mean direction
  ``m = (C, S)`` to the pin velocity ``v_i``: ``atan2(cross(m, v_i), dot(m,
  v_i))``, already in ``[-pi, pi]`` (no separate wrap; neither ``m`` nor ``v_i``
  needs unit length).
* ONNX has no Atan2: ``atan(y / x)`` plus ``+-pi`` when ``x < 0`` (``+pi`` for
  ``y >= 0``), ``+-pi/2`` when ``x == 0``. A shifted angle of exactly ``-pi`` maps
  to ``+pi`` like :func:`~slipkit.features.pins.wrap_angle`; unshifted angles keep
  numpy's sign-of-zero rule (``atan2(-0.0, -1) = -pi``).

Everything up to the final cast runs in float64 (for the mean of nearly
cancelling unit vectors float32 would turn rounding noise into a direction),
except ``Atan``, which onnxruntime 1.31 implements for float32 only: about 1e-7
rad of error. Pins moving exactly against the frame's mean direction sit on the
``+-pi`` branch cut, where rounding can put the graph and numpy on opposite
sides (a 2 pi difference); compare such angles circularly.
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


def _atan2(g: GraphBuilder, y: str, x: str, *, zero_sign: bool) -> str:
    """atan2(y, x) in float64 from Atan + Where (quadrant rules); see the module notes.

    ``zero_sign`` keeps numpy's rule that ``y = -0.0`` with ``x < 0`` gives
    ``-pi``; without it both zeros give ``+pi`` (the ``(-pi, pi]`` wrap).
    """
    zero = g.const(0.0, np.float64)
    one = g.const(1.0, np.float64)
    x_zero = g.op("Equal", x, zero)
    safe_x = g.op("Where", x_zero, one, x)
    ratio = g.op("Cast", g.op("Div", y, safe_x), to=FLOAT)
    base = g.op("Cast", g.op("Atan", ratio), to=DOUBLE)
    if zero_sign:
        # 1 / -0.0 = -inf: the sign bit of a zero y decides the half-plane, as in numpy.
        upper = g.op("Greater", g.op("Div", one, y), zero)
    else:
        upper = g.op("GreaterOrEqual", y, zero)
    pi, minus_pi = g.const(math.pi, np.float64), g.const(-math.pi, np.float64)
    offset = g.op(
        "Where",
        g.op("Less", x, zero),
        g.op("Where", upper, pi, minus_pi),
        zero,
    )
    half_pi = g.const(math.pi / 2.0, np.float64)
    vertical = g.op("Mul", g.op("Sign", y), half_pi)  # x == 0: +-pi/2, 0 for y == 0
    return g.op("Where", x_zero, vertical, g.op("Add", base, offset))


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
    p = g.op("Cast", pins, to=DOUBLE)
    prev = g.op("Gather", p, g.const(0, np.int64), axis=1)
    cur = g.op("Gather", p, g.const(1, np.int64), axis=1)
    v = g.op("Sub", cur, prev)  # (batch, 2N): dx0..dx{N-1}, dy0..dy{N-1}
    first = (g.const([0], np.int64), g.const([n], np.int64))
    second = (g.const([n], np.int64), g.const([2 * n], np.int64))
    axis1 = g.const([1], np.int64)
    bad = g.op("IsNaN", g.op("Sub", v, v))  # not finite (see module notes)
    missing = g.op(
        "Or",
        g.op("Slice", bad, *first, axis1),
        g.op("Slice", bad, *second, axis1),
    )
    zero = g.const(0.0, np.float64)
    dx = g.op("Where", missing, zero, g.op("Slice", v, *first, axis1))
    dy = g.op("Where", missing, zero, g.op("Slice", v, *second, axis1))
    dr = g.op("Sqrt", g.op("Add", g.op("Mul", dx, dx), g.op("Mul", dy, dy)))
    parts: list[str] = []
    if variant in ("dr_dtheta", "dr"):
        parts.append(dr)
    if variant in ("dr_dtheta", "dtheta"):
        has_angle = g.op("Greater", dr, zero)
        if shift_angles:
            one = g.const(1.0, np.float64)
            inv = g.op("Div", one, g.op("Where", has_angle, dr, one))
            # Pins without an angle have dx = dy = 0, so they add nothing to C and S.
            ux, uy = g.op("Mul", dx, inv), g.op("Mul", dy, inv)
            c = g.op("ReduceSum", ux, axis1, keepdims=1)
            s = g.op("ReduceSum", uy, axis1, keepdims=1)
            count = g.op(
                "ReduceSum", g.op("Cast", has_angle, to=DOUBLE), axis1, keepdims=1
            )
            resultant = g.op(
                "Div",
                g.op("Sqrt", g.op("Add", g.op("Mul", c, c), g.op("Mul", s, s))),
                g.op("Max", count, one),
            )
            directed = g.op("Greater", resultant, g.const(RESULTANT_EPS, np.float64))
            mc = g.op("Where", directed, c, one)
            ms = g.op("Where", directed, s, zero)
            # Unit vectors, not raw velocities: the angle is scale-free, and tiny
            # velocities would otherwise lose their direction to underflow in the products.
            cross = g.op("Sub", g.op("Mul", mc, uy), g.op("Mul", ms, ux))
            dot = g.op("Add", g.op("Mul", mc, ux), g.op("Mul", ms, uy))
            theta = _atan2(g, cross, dot, zero_sign=False)
        else:
            theta = _atan2(g, dy, dx, zero_sign=True)
        parts.append(g.op("Where", has_angle, theta, zero))
    if missing_count:
        parts.append(
            g.op("ReduceSum", g.op("Cast", missing, to=DOUBLE), axis1, keepdims=1)
        )
    feats = parts[0] if len(parts) == 1 else g.op("Concat", *parts, axis=1)
    return g.op("Cast", feats, to=FLOAT, stem="features")


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
