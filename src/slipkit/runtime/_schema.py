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


def _kind(value: object) -> str:
    return "null" if value is None else type(value).__name__


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
                key, f"must be a non-empty string; got {_kind(value)} {value!r}"
            )
        if choices is not None and value not in choices:
            raise self.error(key, f"must be one of {list(choices)}; got {value!r}")
        return value

    def integer(
        self, key: str, default: Any = _MISSING, *, minimum: int | None = None
    ) -> int:
        """An integer (JSON booleans refused), optionally ``>= minimum``."""
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"must be an integer; got {_kind(value)} {value!r}")
        if minimum is not None and value < minimum:
            raise self.error(key, f"must be >= {minimum}; got {value}")
        return value

    def number(
        self, key: str, default: Any = _MISSING, *, positive: bool = False
    ) -> float:
        """A finite number (int or float; booleans refused), optionally > 0."""
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, f"must be a number; got {_kind(value)} {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(key, f"must be finite; got {value}")
        if positive and value <= 0:
            raise self.error(key, f"must be > 0; got {value}")
        return value

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        """A JSON boolean."""
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(
                key, f"must be true or false; got {_kind(value)} {value!r}"
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
                key, f"must be a non-empty list of non-empty strings; got {value!r}"
            )
        if unique and len(set(value)) != len(value):
            dup = sorted({v for v in value if value.count(v) > 1})
            raise self.error(key, f"must not repeat names; repeated: {dup}")
        return tuple(value)

    def integers(
        self, key: str, default: Any = _MISSING, *, minimum: int = 1
    ) -> tuple[int, ...]:
        """A non-empty list of integers, each ``>= minimum``."""
        value = self.raw(key, default)
        if (
            not isinstance(value, list)
            or not value
            or not all(
                isinstance(v, int) and not isinstance(v, bool) and v >= minimum
                for v in value
            )
        ):
            raise self.error(
                key, f"must be a non-empty list of integers >= {minimum}; got {value!r}"
            )
        return tuple(value)

    def array(self, key: str) -> NDArray[np.float64]:
        """A non-empty (nested) list of finite numbers as a float64 array."""
        value = self.raw(key)
        if not isinstance(value, list):
            raise self.error(key, f"must be a list of numbers; got {_kind(value)}")
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
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
