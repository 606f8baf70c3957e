"""Typed reads of manifest fields; every failure names the file and the dotted field.

Hand-written rather than a JSON-Schema library: the runtime extra is numpy +
onnxruntime only, and the checks need numpy-aware parts (finite float arrays) that a
schema library would not give anyway.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slipkit.runtime.errors import BundleError

_MISSING: Any = object()

# -- bounds ------------------------------------------------------------------------------
# Every number a manifest gives is bounded, so that no value can make the runtime
# allocate without limit, start a million threads or spin for hours (docs/deploy.md,
# "Bounded fields"). The bounds are far above any sensor slipkit knows (a 346 x 260
# DAVIS frame is 90k values; the longest window, SlipTack's, is 300 frames).

#: Largest manifest.json read, bytes.
MAX_MANIFEST_BYTES = 64 << 20
#: Deepest JSON nesting accepted anywhere in a manifest (objects and lists).
MAX_JSON_DEPTH = 32
#: Largest model.onnx read, bytes (protobuf's own limit is 2 GiB).
MAX_MODEL_BYTES = 2 << 30
#: Most values in one frame, in one graph input or output, and in one window
#: (``window x`` frame values: the loop's ring buffer holds twice that in float64, 64 MiB).
MAX_VALUES = 1 << 22
#: Most frames in a window, between decisions (hop), and in a baseline.
MAX_FRAMES = 100_000
#: Fastest frame rate, Hz.
MAX_RATE_HZ = 1e6
#: Longest debounce (consecutive slip decisions).
MAX_DEBOUNCE_K = 10_000
#: Longest frame period, ms (one minute).
MAX_FRAME_PERIOD_MS = 60_000.0
#: Most onnxruntime threads per pool.
MAX_THREADS = 64
#: Most warm-up calls before the first frame.
MAX_WARMUP = 10_000
#: Highest ONNX opset number accepted.
MAX_OPSET = 99
#: Most preprocessing steps.
MAX_STEPS = 64


def json_depth(obj: object) -> int:
    """Nesting depth of a decoded JSON value (a scalar is 0, ``[]`` and ``{}`` are 1).

    Iterative, so a value nested deeper than Python's recursion limit is measured
    rather than crashing the measurement.
    """
    deepest = 0
    stack: list[tuple[object, int]] = [(obj, 0)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict):
            children: Any = value.values()
        elif isinstance(value, list):
            children = value
        else:
            continue
        depth += 1
        deepest = max(deepest, depth)
        stack.extend((child, depth) for child in children)
    return deepest


def _kind(value: object) -> str:
    return "null" if value is None else type(value).__name__


def _short(value: object, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters (a message stays one short line)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**30:
        return f"an integer of {value.bit_length()} bits"
    try:
        text = repr(value)
    except ValueError:  # holds an integer beyond str()'s digit limit
        return f"a {_kind(value)} holding a huge integer"
    return text if len(text) <= limit else text[: limit - 3] + "..."


class Fields:
    """A JSON object being read, with its file name and dotted path for messages.

    Parameters
    ----------
    file : str
        The file the object came from (named in every error).
    obj : object
        The decoded JSON value; must be a dict.
    path : str
        Dotted path of ``obj`` inside the file (``""`` for the top level).
    """

    def __init__(self, file: str, obj: object, path: str = "") -> None:
        self.file = file
        self.path = path
        if not isinstance(obj, dict):
            raise BundleError(
                file, path or None, f"must be a JSON object; got {_kind(obj)}"
            )
        self.obj: dict[str, Any] = obj

    def name(self, key: str | int) -> str:
        """Dotted name of a child field (``frame.shape``, ``preprocessing[0]``)."""
        if isinstance(key, int):
            return f"{self.path}[{key}]"
        return f"{self.path}.{key}" if self.path else key

    def error(self, key: str | int | None, problem: str) -> BundleError:
        """A :class:`BundleError` for ``key`` (None: this object itself)."""
        return BundleError(
            self.file, self.path or None if key is None else self.name(key), problem
        )

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        """The field's JSON value; a missing required field is an error."""
        if key in self.obj:
            return self.obj[key]
        if default is _MISSING:
            raise self.error(key, "is missing (required)")
        return default

    def child(self, key: str, default: Any = _MISSING) -> Fields:
        """A nested object as :class:`Fields` (an absent optional one reads as ``{}``)."""
        return Fields(self.file, self.raw(key, default), self.name(key))

    def string(
        self, key: str, default: Any = _MISSING, *, choices: Sequence[str] | None = None
    ) -> str:
        """A non-empty string, optionally one of ``choices``."""
        value = self.raw(key, default)
        if not isinstance(value, str) or not value:
            raise self.error(
                key, f"must be a non-empty string; got {_kind(value)} {_short(value)}"
            )
        if choices is not None and value not in choices:
            raise self.error(
                key, f"must be one of {list(choices)}; got {_short(value)}"
            )
        return value

    def integer(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        minimum: int | None = None,
        maximum: int | None = None,
    ) -> int:
        """An integer (JSON booleans refused), optionally in ``[minimum, maximum]``."""
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(
                key, f"must be an integer; got {_kind(value)} {_short(value)}"
            )
        if minimum is not None and value < minimum:
            raise self.error(key, f"must be >= {minimum}; got {_short(value)}")
        if maximum is not None and value > maximum:
            raise self.error(key, f"must be <= {maximum}; got {_short(value)}")
        return value

    def number(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        positive: bool = False,
        maximum: float | None = None,
    ) -> float:
        """A finite number (int or float; booleans refused), optionally > 0 and <= ``maximum``."""
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(
                key, f"must be a number; got {_kind(value)} {_short(value)}"
            )
        try:
            value = float(value)
        except OverflowError:  # an integer beyond float64
            raise self.error(key, f"must be finite; got {_short(value)}") from None
        if not math.isfinite(value):
            raise self.error(key, f"must be finite; got {value}")
        if positive and value <= 0:
            raise self.error(key, f"must be > 0; got {value}")
        if maximum is not None and value > maximum:
            raise self.error(key, f"must be <= {maximum:g}; got {value:g}")
        return value

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        """A JSON boolean."""
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(
                key, f"must be true or false; got {_kind(value)} {_short(value)}"
            )
        return value

    def strings(
        self, key: str, default: Any = _MISSING, *, unique: bool = False
    ) -> tuple[str, ...]:
        """A non-empty list of non-empty strings, optionally without repeats."""
        value = self.raw(key, default)
        if (
            not isinstance(value, list)
            or not value
            or not all(isinstance(v, str) and v for v in value)
        ):
            raise self.error(
                key,
                f"must be a non-empty list of non-empty strings; got {_short(value)}",
            )
        if unique and len(set(value)) != len(value):
            dup = sorted({v for v in value if value.count(v) > 1})
            raise self.error(key, f"must not repeat names; repeated: {dup}")
        return tuple(value)

    def integers(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        minimum: int = 1,
        maximum: int = MAX_VALUES,
        max_product: int | None = None,
    ) -> tuple[int, ...]:
        """A non-empty list of integers in ``[minimum, maximum]``.

        ``max_product`` bounds the product (a shape's number of values) too.
        """
        value = self.raw(key, default)
        if (
            not isinstance(value, list)
            or not value
            or not all(
                isinstance(v, int)
                and not isinstance(v, bool)
                and minimum <= v <= maximum
                for v in value
            )
        ):
            raise self.error(
                key,
                f"must be a non-empty list of integers in [{minimum}, {maximum}]; "
                f"got {_short(value)}",
            )
        if max_product is not None:
            product = 1
            for v in value:  # stops early: a long list of large dims is no big int
                product *= v
                if product > max_product:
                    raise self.error(
                        key,
                        f"{_short(value)} holds more than {max_product} values "
                        "(the most accepted)",
                    )
        return tuple(value)

    def array(self, key: str) -> NDArray[np.float64]:
        """A non-empty (nested) list of finite numbers as a float64 array."""
        value = self.raw(key)
        if not isinstance(value, list):
            raise self.error(key, f"must be a list of numbers; got {_kind(value)}")
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise self.error(
                key, "must be a (nested, rectangular) list of numbers"
            ) from None
        if arr.size == 0:
            raise self.error(key, "must not be empty")
        if not np.all(np.isfinite(arr)):
            raise self.error(key, "must hold finite numbers only (no NaN or inf)")
        return arr

    def only(self, allowed: Sequence[str]) -> None:
        """Refuse keys outside ``allowed`` (a typo must not pass silently)."""
        extra = sorted(set(self.obj) - set(allowed))
        if extra:
            raise self.error(
                extra[0], f"is not a known field here; allowed: {sorted(allowed)}"
            )
