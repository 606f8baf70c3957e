"""FSR (Gentile et al. 2020): the 4th-order voltage-to-force calibration and its inverse,
and the slip-event count law fitted to the paper's Table 3.

Calibration (eq. 6): ``F = p1 V^4 + p2 V^3 + p3 V^2 + p4 V + p5`` (N from V). The paper
does not print its coefficients; :data:`DEFAULT_CALIBRATION` is a documented assumption:
the expansion of ``F = a u + b u^4`` with ``u = V_rest - V``, ``V_rest = 4.5 V``,
``a = 0.5 N/V``, ``b = 0.0217 N/V^4``. The conditioned voltage falls as the force rises
(the paper: a negative voltage derivative is a pressure increment), steeply at light
load and less so at heavy load, as an FSR does: 0 N -> 4.5 V, 1.2 N -> 2.63 V,
4.7 N -> 1.07 V, 5 N -> 1.0 V, so 0-5 N stays inside a 0-5 V output.

numpy only.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: ``(p1, p2, p3, p4, p5)`` of eq. 6 (N/V^4 ... N), see the module docstring.
DEFAULT_CALIBRATION: tuple[float, float, float, float, float] = (
    0.0217,
    -0.3906,
    2.63655,
    -8.40965,
    11.14835625,
)

#: The conditioned output's range (V).
OUTPUT_RANGE_V: tuple[float, float] = (0.0, 5.0)

#: Table 3 of the paper, the four corners the count law is fitted to:
#: (normal force N, pass duration s, mean slip events per pass).
TABLE3_CORNERS: tuple[tuple[float, float, float], ...] = (
    (1.2, 5.0, 37.6),
    (1.2, 1.0, 17.4),
    (4.7, 5.0, 55.7),
    (4.7, 1.0, 28.4),
)

#: Least-squares fit of ``log N = log c + alpha log F + beta log T`` to
#: :data:`TABLE3_CORNERS`: every corner within 2.5%.
SLIP_COUNT_COEFF = 16.81
SLIP_COUNT_FORCE_EXPONENT = 0.3233
SLIP_COUNT_PASS_EXPONENT = 0.4486


def force_from_voltage(
    voltage_V: ArrayLike, coeffs: Sequence[float] = DEFAULT_CALIBRATION
) -> FloatArray:
    """Eq. 6: force (N) from the conditioned voltage (V)."""
    p = np.asarray(coeffs, dtype=np.float64)
    return np.asarray(
        np.polyval(p, np.asarray(voltage_V, dtype=np.float64)), dtype=np.float64
    )


@lru_cache(maxsize=32)
def _branch(
    coeffs: tuple[float, ...], v_lo: float, v_hi: float
) -> tuple[float, float, FloatArray, FloatArray]:
    """(V_rest, V_low, F table ascending, V table) of the calibration's monotonic branch."""
    p = np.asarray(coeffs, dtype=np.float64)
    dp = np.polyder(p)
    roots = np.roots(p)
    real = roots[np.abs(roots.imag) < 1e-9].real
    rest = [r for r in real if v_lo <= r <= v_hi and np.polyval(dp, r) < 0]
    if not rest:
        raise ValueError(
            f"calibration {list(coeffs)} has no zero-force voltage in [{v_lo}, {v_hi}] V "
            "where force falls with voltage"
        )
    v_rest = float(max(rest))
    turns = np.roots(dp) if len(dp) > 1 else np.array([])
    turns = turns[np.abs(turns.imag) < 1e-9].real
    below = [r for r in turns if v_lo <= r < v_rest]
    v_low = float(max(below)) if below else v_lo
    v = np.linspace(v_rest, v_low, 4097)
    f = np.asarray(np.polyval(p, v), dtype=np.float64)
    f[0] = 0.0
    return v_rest, v_low, f, v


def rest_voltage(
    coeffs: Sequence[float] = DEFAULT_CALIBRATION,
    output_range_V: Sequence[float] = OUTPUT_RANGE_V,
) -> float:
    """The conditioned voltage at zero force (V): the calibration's zero on its falling branch."""
    return _branch(tuple(map(float, coeffs)), *map(float, output_range_V))[0]


def max_force(
    coeffs: Sequence[float] = DEFAULT_CALIBRATION,
    output_range_V: Sequence[float] = OUTPUT_RANGE_V,
) -> float:
    """The largest force (N) the calibration maps inside the output range."""
    return float(_branch(tuple(map(float, coeffs)), *map(float, output_range_V))[2][-1])


def voltage_from_force(
    force_N: ArrayLike,
    coeffs: Sequence[float] = DEFAULT_CALIBRATION,
    output_range_V: Sequence[float] = OUTPUT_RANGE_V,
) -> FloatArray:
    """Inverse of eq. 6 on its falling branch: the conditioned voltage (V) for a force (N).

    Forces are clipped to ``[0, max_force]``: a negative force reads as rest, a force
    beyond the branch saturates at its low end (the output rail). Interpolation in a
    4097-point table, polished by one Newton step (error far below a microvolt).
    """
    p = tuple(map(float, coeffs))
    _, _, f_tab, v_tab = _branch(p, *map(float, output_range_V))
    f = np.clip(np.asarray(force_N, dtype=np.float64), 0.0, f_tab[-1])
    v = np.interp(f, f_tab, v_tab)
    arr = np.asarray(p)
    slope = np.polyval(np.polyder(arr), v)
    step = np.where(
        slope < 0, (np.polyval(arr, v) - f) / np.where(slope < 0, slope, 1.0), 0.0
    )
    return np.asarray(v - step, dtype=np.float64)


def expected_slip_events(
    force_N: ArrayLike,
    pass_s: ArrayLike,
    coeff: float = SLIP_COUNT_COEFF,
    force_exponent: float = SLIP_COUNT_FORCE_EXPONENT,
    pass_exponent: float = SLIP_COUNT_PASS_EXPONENT,
) -> FloatArray:
    """Mean slip events in one probe pass, ``N = c F^alpha T^beta`` (Table 3 fit).

    More events at higher normal force ``F`` (N); fewer per pass for shorter passes ``T``
    (s), yet ``beta < 1`` so the rate ``N / T`` rises with sliding speed.
    """
    f = np.asarray(force_N, dtype=np.float64)
    t = np.asarray(pass_s, dtype=np.float64)
    return np.asarray(coeff * f**force_exponent * t**pass_exponent, dtype=np.float64)
