"""Progress lines of a long training step (fold i of n, elapsed, ETA) on stderr.

``slipkit train`` prints them so a user sees a long cross-validation move. A caller
that shows its own progress (``slipkit compare`` and the demo: one bar per run) quiets
them for a block with :func:`quiet_progress`; warnings and errors still print. A
context variable, not a global flag, so a quieted block does not quiet another thread.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

_QUIET: ContextVar[bool] = ContextVar("slipkit_quiet_progress", default=False)


def progress_line(text: str) -> None:
    """Print ``text`` on stderr, unless inside :func:`quiet_progress`."""
    if not _QUIET.get():
        print(text, file=sys.stderr, flush=True)


@contextmanager
def quiet_progress() -> Iterator[None]:
    """Keep :func:`progress_line` silent inside the block."""
    token = _QUIET.set(True)
    try:
        yield
    finally:
        _QUIET.reset(token)


__all__ = ["progress_line", "quiet_progress"]
