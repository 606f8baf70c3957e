"""One set of checks for the numbers a scene, an effect or a plant reads from its config.

A parameter is a number or, where the scene draws it per trial, a ``[low, high]`` range; a
bad one is a :class:`~slipkit.sim.core.SimulationError` that names the key and the value, in
the same words for every scene, effect and plant:

- :func:`number`: one finite number within optional bounds;
- :func:`value_range`: a number (a fixed value) or ``[low, high]``, finite, ``low <= high``,
  within the same bounds;
- :func:`single`: a range that must be one number;
- :func:`draw`: the per-trial value of a range (the low end when it is fixed, without
  consuming the random stream, so a fixed range draws as before).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from slipkit.sim.core import SimulationError

Range = tuple[float, float]


def _bounds_text(lo: float | None, hi: float | None, strict_lo: bool) -> str:
    parts = []
    if lo is not None:
        parts.append(f"{'>' if strict_lo else '>='} {lo:g}")
    if hi is not None:
        parts.append(f"<= {hi:g}")
    return " and ".join(parts)


def number(
    key: str,
    value: Any,
    *,
    lo: float | None = None,
    hi: float | None = None,
    strict_lo: bool = False,
) -> float:
    """``value`` as a finite float within ``[lo, hi]`` (``(lo, hi]`` with ``strict_lo``)."""
    if isinstance(value, bool | str):
        raise SimulationError(f"{key} must be a number; got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise SimulationError(f"{key} must be a number; got {value!r}") from None
    if not math.isfinite(x):
        raise SimulationError(f"{key} must be finite; got {value!r}")
    low_bad = lo is not None and (x <= lo if strict_lo else x < lo)
    if low_bad or (hi is not None and x > hi):
        raise SimulationError(
            f"{key} must be {_bounds_text(lo, hi, strict_lo)}; got {x:g}"
        )
    return x


def value_range(
    key: str,
    value: Any,
    *,
    lo: float | None = None,
    hi: float | None = None,
    strict_lo: bool = False,
) -> Range:
    """A number (fixed) or ``[low, high]``: finite, ``low <= high``, both within bounds."""
    if isinstance(value, Sequence) and not isinstance(value, str):
        items = list(value)
        if len(items) == 1:
            items = items * 2
        if len(items) != 2:
            raise SimulationError(
                f"{key} must be a number or [low, high]; got {value!r}"
            )
        a, b = (number(key, v) for v in items)
    else:
        a = b = number(key, value)
    if b < a:
        raise SimulationError(f"{key} must have low <= high; got [{a:g}, {b:g}]")
    number(key, a, lo=lo, hi=hi, strict_lo=strict_lo)
    number(key, b, lo=lo, hi=hi, strict_lo=strict_lo)
    return (a, b)


def single(
    key: str,
    value: Any,
    *,
    lo: float | None = None,
    hi: float | None = None,
    strict_lo: bool = False,
) -> float:
    """A parameter that must be one number (a ``[x, x]`` range is accepted as ``x``)."""
    a, b = value_range(key, value, lo=lo, hi=hi, strict_lo=strict_lo)
    if a != b:
        raise SimulationError(f"{key} must be a single number; got [{a:g}, {b:g}]")
    return a


def draw(
    rng: np.random.Generator,
    r: Range,
    size: int | None = None,
    *,
    skip_fixed: bool = True,
) -> Any:
    """The per-trial value of ``r``: uniform in ``[low, high]``. A fixed range (one number)
    returns it without drawing when ``skip_fixed`` (the random stream is not consumed), unless
    ``size`` asks for an array."""
    if skip_fixed and size is None and r[0] == r[1]:
        return float(r[0])
    out = rng.uniform(r[0], r[1], size=size)
    return out if size is not None else float(out)


__all__ = ["Range", "draw", "number", "single", "value_range"]
