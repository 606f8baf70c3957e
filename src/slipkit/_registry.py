"""One registry type for every plug-in table (exporters, deployers, adapters, effects,
closed-loop scenarios, the runtime's preprocessing ops).

A :class:`Registry` is a read-only mapping with one way in, :meth:`Registry.register`, which

- refuses a second entry under a key unless ``overwrite=True`` (as sklearn-onnx's
  ``register_converter``), re-registering the very same object being a no-op (a module
  imported twice under two names registers once);
- checks that the entry is callable with the positional parameters its kind takes, so a
  plug-in with the wrong signature fails where it is registered, not deep inside a run.

Class-keyed registries look an object up along its class's MRO (:meth:`Registry.for_class`):
a subclass inherits its base's entry unless it registers its own.

Standard library only: the gripper-PC runtime uses it for its op table. Written here rather
than taken from a library because the ones that exist (entry points, ``catalogue``) register
by name only and check neither duplicates against an error type of our choosing nor signatures.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator, Mapping
from typing import Any, Generic, TypeVar

K = TypeVar("K")
V = TypeVar("V")


def _label(key: Any) -> str:
    if isinstance(key, type):
        return f"{key.__module__}.{key.__qualname__}"
    return repr(key)


def accepts_positional(fn: Any, n: int) -> bool:
    """Whether ``fn`` can be called with ``n`` positional arguments (unknown: True)."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):  # a builtin without a signature: trust it
        return True
    positional = (
        inspect.Parameter.POSITIONAL_ONLY,
        inspect.Parameter.POSITIONAL_OR_KEYWORD,
    )
    params = list(sig.parameters.values())
    takes = [p for p in params if p.kind in positional]
    needs = [p for p in takes if p.default is inspect.Parameter.empty]
    star = any(p.kind is inspect.Parameter.VAR_POSITIONAL for p in params)
    # keyword-only parameters are the entry's options (an effect's scene parameters)
    return len(needs) <= n and (star or len(takes) >= n)


class Registry(Mapping[K, V], Generic[K, V]):
    """A named table of plug-ins that refuses duplicates and checks signatures.

    Parameters
    ----------
    kind : str
        What an entry is ("exporter", "preprocessing op"): used in every message.
    error : type of Exception
        Raised for a duplicate or a bad entry (e.g. ``ExportError``, ``ValueError``).
    n_args : int, optional
        The positional parameters an entry is called with; ``None``: entries are not
        called (classes, tables) and only need to exist.
    key_type : type, optional
        Keys must be instances of it (``type`` for class-keyed registries).
    """

    def __init__(
        self,
        kind: str,
        *,
        error: type[Exception] = ValueError,
        n_args: int | None = None,
        key_type: type | None = None,
    ) -> None:
        self.kind = kind
        self.error = error
        self.n_args = n_args
        self.key_type = key_type
        self._entries: dict[K, V] = {}

    # -- the mapping view --------------------------------------------------------------
    def __getitem__(self, key: K) -> V:
        return self._entries[key]

    def __iter__(self) -> Iterator[K]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {len(self)} entries)"

    # -- the one way in ----------------------------------------------------------------
    def register(self, key: K, value: V, *, overwrite: bool = False) -> V:
        """Add ``value`` under ``key``; returns ``value`` (usable inside decorators)."""
        if self.key_type is not None and not isinstance(key, self.key_type):
            raise TypeError(
                f"{self.kind} registry: the key must be a {self.key_type.__name__}; "
                f"got {key!r}"
            )
        if self.n_args is not None:
            if not callable(value):
                raise TypeError(
                    f"{self.kind} for {_label(key)} is not callable: {value!r}"
                )
            if not accepts_positional(value, self.n_args):
                raise TypeError(
                    f"{self.kind} for {_label(key)} ({_label(value)}) must accept "
                    f"{self.n_args} positional argument(s); its signature is "
                    f"{inspect.signature(value)}"
                )
        old = self._entries.get(key)
        if old is not None and old is not value and not overwrite:
            raise self.error(
                f"a {self.kind} is already registered for {_label(key)} "
                f"({_label(old)}); pass overwrite=True to replace it"
            )
        self._entries[key] = value
        return value

    def decorator(self, key: K, *, overwrite: bool = False) -> Callable[[V], V]:
        """``@registry.decorator(key)``: register the decorated object under ``key``."""

        def deco(value: V) -> V:
            return self.register(key, value, overwrite=overwrite)

        return deco

    def unregister(self, key: K) -> None:
        """Remove ``key``'s entry (KeyError if none): for tests and plug-in reloads."""
        del self._entries[key]

    def for_class(self, cls: type) -> V | None:
        """The entry of ``cls`` or of its nearest registered base class (None if none)."""
        for base in cls.__mro__:
            if base in self._entries:
                return self._entries[base]
        return None
