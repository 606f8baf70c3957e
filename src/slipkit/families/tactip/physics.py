"""TacTip geometry and contact physics (numpy only).

The TacTip (James, Pestell, Lepora 2018, RA-L 3(4), Sec. III-A) images 127 pins on
the inside of its hemispherical skin, "arranged in a hexagonal pattern". Here the
pins are laid out in the camera's image plane, in millimetres, with the origin at
the sensor centre, +x to the right and +y up (against gravity in the drop rig).

Pin stream layout
-----------------
A ``pins`` stream holds ``2 * N`` channels: ``x0 .. x{N-1}`` then ``y0 .. y{N-1}``
(all x first, then all y), in mm. Pin ``i`` is the ``i``-th entry of
:func:`pin_layout`: pin 0 is the centre, then ring 1 (6 pins), ring 2 (12 pins)...
each ring ordered counter-clockwise from +x. :func:`split_pins` and
:func:`join_pins` convert between this flat layout and ``(..., N, 2)`` arrays.

Contact model (assumptions, documented in ``docs/families/tactip.md``)
-----------------------------------------------------------------------
Normal force follows Hertz, ``F_n = K δ^1.5`` (δ indentation, mm). The contact patch
is an ellipse with semi-axes ``a = sqrt(R δ)`` along each axis, where ``R`` is the
effective radius ``1 / (1 / R_tip + 1 / R_obj)`` (``R_obj = inf`` for a flat
stimulus). Curved stimuli are cylinders with their axis vertical (the paper mounts
them "such that their curvature was aligned to the vertical axis"), so they curve
across x only. The pre-slip tangential stretch follows the Cattaneo-Mindlin
partial-slip law for a constant tangential load on a Hertz contact.
"""

from __future__ import annotations

import math
import re

import numpy as np

#: Pins of the TacTip in the paper (James et al. 2018, Sec. III-A1).
TACTIP_PINS = 127

_OBJECT = re.compile(r"^r(\d+(?:\.\d+)?)$")


def pins_in_rings(n_rings: int) -> int:
    """Pins of a full hexagonal grid of ``n_rings`` rings around a centre pin.

    ``1 + 3 n (n + 1)``: 6 rings give the TacTip's 127 pins.

    >>> pins_in_rings(6)
    127
    """
    if n_rings < 0:
        raise ValueError(f"n_rings must be >= 0; got {n_rings}")
    return 1 + 3 * n_rings * (n_rings + 1)


def pin_layout(n_pins: int = TACTIP_PINS, pitch_mm: float = 3.0) -> np.ndarray:
    """Pin centres (x, y) in mm on a hexagonal grid, centre first, ring by ring.

    Parameters
    ----------
    n_pins : int
        Number of pins. A centred hexagonal number (1, 7, 19, 37, 61, 91, 127...)
        gives full rings; any other count keeps the innermost ``n_pins`` pins.
    pitch_mm : float
        Distance between neighbouring pins, mm.

    Returns
    -------
    ndarray of shape (n_pins, 2)
        ``[:, 0]`` is x and ``[:, 1]`` is y, mm. Within a ring, pins run
        counter-clockwise from the +x axis.
    """
    if n_pins < 1:
        raise ValueError(f"n_pins must be >= 1; got {n_pins}")
    if not pitch_mm > 0:
        raise ValueError(f"pitch_mm must be > 0; got {pitch_mm}")
    n_rings = 0
    while pins_in_rings(n_rings) < n_pins:
        n_rings += 1
    span = np.arange(-n_rings, n_rings + 1)
    q = np.tile(span, len(span))
    r = np.repeat(span, len(span))
    ring = np.maximum.reduce([np.abs(q), np.abs(r), np.abs(q + r)])
    keep = ring <= n_rings
    q, r, ring = q[keep], r[keep], ring[keep]
    x = pitch_mm * (q + 0.5 * r)
    y = pitch_mm * (math.sqrt(3.0) / 2.0) * r
    angle = np.mod(np.arctan2(y, x), 2.0 * np.pi)
    # Round the angle so the order does not hinge on floating-point ties.
    order = np.lexsort((np.round(angle, 9), ring))[:n_pins]
    return np.column_stack([x[order], y[order]])


def pin_channels(n_pins: int = TACTIP_PINS) -> tuple[str, ...]:
    """Channel names of a pins stream: ``x0 .. x{N-1}`` then ``y0 .. y{N-1}``."""
    if n_pins < 1:
        raise ValueError(f"n_pins must be >= 1; got {n_pins}")
    return tuple(f"x{i}" for i in range(n_pins)) + tuple(f"y{i}" for i in range(n_pins))


def split_pins(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split a ``(..., 2N)`` pins array (x block then y block) into x and y, each ``(..., N)``."""
    values = np.asarray(values)
    if values.shape[-1] % 2:
        raise ValueError(
            f"a pins array needs an even last axis (2N); got {values.shape}"
        )
    n = values.shape[-1] // 2
    return values[..., :n], values[..., n:]


def join_pins(xy: np.ndarray) -> np.ndarray:
    """Flatten ``(..., N, 2)`` pin positions into the stream layout ``(..., 2N)``."""
    xy = np.asarray(xy)
    if xy.ndim < 2 or xy.shape[-1] != 2:
        raise ValueError(f"expected pin positions of shape (..., N, 2); got {xy.shape}")
    return np.concatenate([xy[..., 0], xy[..., 1]], axis=-1)


def object_radius_mm(label: str) -> float:
    """Radius of curvature (mm) of a stimulus label: ``"flat"`` -> inf, ``"r40"`` -> 40.0."""
    if label == "flat":
        return math.inf
    match = _OBJECT.match(label)
    if match is None or float(match.group(1)) <= 0:
        raise ValueError(
            f"object label {label!r}: expected 'flat' or 'r<radius mm>' (e.g. 'r40')"
        )
    return float(match.group(1))


def normal_force_N(indentation_mm: np.ndarray, stiffness: float) -> np.ndarray:
    """Hertz normal force ``F_n = K δ^1.5`` (N) for indentation δ (mm), ``K`` in N/mm^1.5."""
    return stiffness * np.clip(indentation_mm, 0.0, None) ** 1.5


def slip_indentation_mm(weight_N: float, mu_s: float, stiffness: float) -> float:
    """Indentation (mm) at which static friction just holds the weight: ``μ_s K δ^1.5 = W``."""
    return float((weight_N / (mu_s * stiffness)) ** (2.0 / 3.0))


def contact_semi_axes(
    indentation_mm: np.ndarray, object_radius: float, tip_radius_mm: float
) -> tuple[np.ndarray, np.ndarray]:
    """Semi-axes (a_x, a_y) in mm of the contact ellipse at indentation δ (mm).

    ``a = sqrt(R δ)`` (Hertz) with ``1 / R_x = 1 / R_tip + 1 / R_obj`` across the
    cylinder's curvature and ``R_y = R_tip`` along its axis; 0 where δ <= 0.
    """
    d = np.clip(np.asarray(indentation_mm, dtype=np.float64), 0.0, None)
    r_x = 1.0 / (1.0 / tip_radius_mm + 1.0 / object_radius)
    return np.sqrt(r_x * d), np.sqrt(tip_radius_mm * d)


def contact_weights(
    rest_xy: np.ndarray, a_x: np.ndarray, a_y: np.ndarray, spread_mm: float
) -> np.ndarray:
    """How strongly each pin follows the contact: 1 inside the patch, decaying outside.

    Outside the ellipse the weight is ``exp(-d / spread)``, with ``d`` the distance
    (mm) from the pin to the ellipse along the ray from the centre; without contact
    (a semi-axis of 0) every weight is 0.

    Parameters
    ----------
    rest_xy : ndarray (N, 2)
        Pin rest positions, mm.
    a_x, a_y : ndarray (T,) or float
        Contact semi-axes, mm.
    spread_mm : float
        Decay length of the skin's coupling outside the contact, mm.

    Returns
    -------
    ndarray (T, N)
    """
    ax = np.atleast_1d(np.asarray(a_x, dtype=np.float64))[:, None]
    ay = np.atleast_1d(np.asarray(a_y, dtype=np.float64))[:, None]
    x, y = rest_xy[None, :, 0], rest_xy[None, :, 1]
    dist = np.hypot(x, y)
    touching = (ax > 0) & (ay > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.sqrt((x / ax) ** 2 + (y / ay) ** 2)
        outside = np.where(rho > 1.0, dist * (1.0 - 1.0 / rho), 0.0)
    w = np.exp(-np.nan_to_num(outside, nan=0.0) / spread_mm)
    return np.where(touching, w, 0.0)


def mindlin_stretch(load_ratio: np.ndarray) -> np.ndarray:
    """Tangential compliance displacement of a Hertz contact, normalised to 1 at slip.

    Cattaneo-Mindlin partial slip (Johnson, *Contact Mechanics*, 1985, Sec. 7.2):
    ``δ_t = 3 μ P / (16 G a) [1 - (1 - Q / (μ P))^(2/3)]`` with ``a ∝ P^(1/3)``.
    For a constant tangential load ``Q`` (the weight) and a falling normal load
    ``P``, write ``ρ = Q / (μ P)``; then ``δ_t / δ_t(ρ = 1) = ρ^(-2/3) [1 - (1 - ρ)^(2/3)]``.
    ``ρ`` is clipped to [0, 1]; 0 gives 0.
    """
    rho = np.clip(np.asarray(load_ratio, dtype=np.float64), 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = rho ** (-2.0 / 3.0) * (1.0 - (1.0 - rho) ** (2.0 / 3.0))
    return np.where(rho > 0, out, 0.0)
