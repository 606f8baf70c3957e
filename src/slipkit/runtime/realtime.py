"""Real-time hygiene for the decision loop: CPU affinity, priority, a frozen GC, pinned threads.

What a robotics engineer sets before a control loop shares a PC with other work
(``docs/deploy.md``, *Deadlines under load*), each an option of ``slipkit-run`` and
measured by ``benchmarks/bench_load.py``:

``cpus``
    :func:`os.sched_setaffinity` of the process (every thread, onnxruntime's
    included) to these cores, so the scheduler does not migrate the loop between
    cores (cold caches) and other processes can be kept off them.
``priority``
    ``"fifo"``: :func:`os.sched_setscheduler` ``SCHED_FIFO`` at ``rt_priority``
    (1-99): the loop preempts every normal process on its cores. ``"nice"``:
    :func:`os.nice` by ``nice`` (negative raises priority). Both need a permission
    (``CAP_SYS_NICE``, or an ``rtprio`` / ``nice`` limit in
    ``/etc/security/limits.conf``); without it the loop runs at its normal priority
    and :func:`apply_realtime` returns one line saying so (never an exception).
``freeze_gc``
    :func:`gc.collect`, then :func:`gc.freeze` (every live object moved to a
    permanent generation the collector never scans) and :func:`gc.disable` while
    the loop runs (:func:`frozen_gc`): no collection pause lands in a decision. The
    loop's hot path allocates no container objects per frame, so nothing piles up.
``pin_threads``
    onnxruntime with one intra-op and one inter-op thread and ``allow_spinning`` as
    chosen (:func:`pinned_session`): no hand-off to a worker thread per node, and no
    spinning worker competing with the loop for its core; and OpenBLAS (numpy's
    matrix products in preprocessing) on one thread (:func:`blas_threads`): on a
    loaded machine its worker threads turned a 1 ms ``sliding_spectrum`` rebuild
    into ~24 ms and a 40 us call's p99 into ~2 ms.

Standard library only (the runtime imports numpy and onnxruntime besides).
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any

from slipkit.runtime.errors import OptionError
from slipkit.runtime.session import SessionSpec

#: ``priority`` choices.
PRIORITIES = ("normal", "nice", "fifo")
#: Default SCHED_FIFO priority (1..99; the kernel's own threads sit at 50 and above).
DEFAULT_RT_PRIORITY = 10
#: Default nice increment of ``priority="nice"`` (-20..19; negative = higher priority).
DEFAULT_NICE = -10


@dataclass(frozen=True)
class RealtimeOptions:
    """The real-time options of a run (module docstring).

    Parameters
    ----------
    cpus : tuple of int, optional
        Cores to pin the process to; None leaves the affinity alone.
    priority : {"normal", "nice", "fifo"}
        Scheduling priority to ask for.
    rt_priority : int
        SCHED_FIFO priority (1..99) for ``priority="fifo"``.
    nice : int
        Nice increment (-20..19) for ``priority="nice"``.
    freeze_gc : bool
        Freeze and disable the garbage collector while the loop runs.
    pin_threads : bool
        One intra-op and one inter-op onnxruntime thread.
    allow_spinning : bool
        onnxruntime's ``session.intra_op.allow_spinning`` with ``pin_threads``.
    """

    cpus: tuple[int, ...] | None = None
    priority: str = "normal"
    rt_priority: int = DEFAULT_RT_PRIORITY
    nice: int = DEFAULT_NICE
    freeze_gc: bool = False
    pin_threads: bool = False
    allow_spinning: bool = False

    def __post_init__(self) -> None:
        if self.priority not in PRIORITIES:
            raise OptionError(
                "--priority",
                f"must be one of {', '.join(PRIORITIES)}; got {self.priority!r}",
            )
        if not 1 <= self.rt_priority <= 99:
            raise OptionError(
                "--priority",
                f"SCHED_FIFO priority must be in [1, 99]; got {self.rt_priority}",
            )
        if not -20 <= self.nice <= 19:
            raise OptionError(
                "--priority", f"nice increment must be in [-20, 19]; got {self.nice}"
            )
        if self.cpus is not None and (not self.cpus or any(c < 0 for c in self.cpus)):
            raise OptionError(
                "--cpus", f"must list one or more core numbers >= 0; got {self.cpus}"
            )

    @property
    def any(self) -> bool:
        """Whether any option asks for a change."""
        return (
            self.cpus is not None
            or self.priority != "normal"
            or self.freeze_gc
            or self.pin_threads
        )

    def to_json(self) -> dict[str, Any]:
        """The options as a JSON-ready dict."""
        return {
            "cpus": None if self.cpus is None else list(self.cpus),
            "priority": self.priority,
            "rt_priority": self.rt_priority,
            "nice": self.nice,
            "freeze_gc": self.freeze_gc,
            "pin_threads": self.pin_threads,
            "allow_spinning": self.allow_spinning,
        }


#: core numbers --cpus takes are below this (Linux's largest usual NR_CPUS): a typo such
#: as 0-999999999 is refused instead of building a set of a billion numbers
MAX_CPUS = 4096


def parse_cpus(text: str) -> tuple[int, ...]:
    """``"0,2-3"`` -> ``(0, 2, 3)``; :class:`OptionError` naming ``--cpus`` otherwise."""
    spans: list[tuple[int, int]] = []
    try:
        for part in text.split(","):
            lo, _, hi = part.strip().partition("-")
            a = int(lo)
            b = int(hi) if hi else a
            if a < 0 or b < a:
                raise ValueError
            spans.append((a, b))
    except ValueError:
        raise OptionError(
            "--cpus", f"must be core numbers and ranges such as 0,2-3; got {text!r}"
        ) from None
    if max(b for _, b in spans) >= MAX_CPUS:
        raise OptionError(
            "--cpus", f"core numbers must be below {MAX_CPUS}; got {text!r}"
        )
    return tuple(sorted({c for a, b in spans for c in range(a, b + 1)}))


def parse_priority(text: str) -> tuple[str, int | None]:
    """``"fifo"``, ``"fifo:20"``, ``"nice"``, ``"nice:-5"``, ``"normal"`` -> (kind, value)."""
    kind, _, value = text.partition(":")
    if kind not in PRIORITIES or (kind == "normal" and value):
        raise OptionError(
            "--priority",
            f"must be normal, nice[:N] (-20..19) or fifo[:N] (1..99); got {text!r}",
        )
    if not value:
        return kind, None
    try:
        return kind, int(value)
    except ValueError:
        raise OptionError(
            "--priority", f"{kind}'s value must be a whole number; got {value!r}"
        ) from None


def options_from_text(
    *,
    cpus: str | None = None,
    priority: str = "normal",
    freeze_gc: bool = False,
    pin_threads: bool = False,
    allow_spinning: bool = False,
) -> RealtimeOptions:
    """:class:`RealtimeOptions` from the command-line texts (checked, errors name the option)."""
    kind, value = parse_priority(priority)
    kw: dict[str, Any] = {}
    if value is not None:
        kw["rt_priority" if kind == "fifo" else "nice"] = value
    return RealtimeOptions(
        cpus=None if cpus is None else parse_cpus(cpus),
        priority=kind,
        freeze_gc=freeze_gc,
        pin_threads=pin_threads,
        allow_spinning=allow_spinning,
        **kw,
    )


#: OpenBLAS's thread-count entry points: plain builds, then numpy's scipy-openblas64.
_BLAS_SET = (
    "openblas_set_num_threads",
    "openblas_set_num_threads64_",
    "scipy_openblas_set_num_threads64_",
    "scipy_openblas_set_num_threads",
)
_BLAS_GET = tuple(name.replace("_set_", "_get_") for name in _BLAS_SET)


def _openblas() -> ctypes.CDLL | None:
    """The OpenBLAS library this process has loaded (Linux: from /proc/self/maps)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        with open("/proc/self/maps") as fh:
            paths = {
                ln.split()[-1] for ln in fh if "openblas" in ln.lower() and "/" in ln
            }
    except OSError:
        return None
    for path in sorted(paths):
        try:
            return ctypes.CDLL(path)
        except OSError:
            continue
    return None


def blas_threads(n: int | None = None) -> int | None:
    """Set OpenBLAS's thread count to ``n`` (if given) and return the count now in force.

    None when no OpenBLAS is loaded (another BLAS, or not Linux). Written by hand with
    :mod:`ctypes` where ``threadpoolctl`` (a well-kept library for exactly this) would
    do, because the runtime may import only the standard library, numpy and
    onnxruntime.
    """
    lib = _openblas()
    if lib is None:
        return None
    setter = next((getattr(lib, s) for s in _BLAS_SET if hasattr(lib, s)), None)
    getter = next((getattr(lib, s) for s in _BLAS_GET if hasattr(lib, s)), None)
    if setter is None or getter is None:
        return None
    if n is not None:
        setter.argtypes, setter.restype = [ctypes.c_int], None
        setter(int(n))
    getter.argtypes, getter.restype = [], ctypes.c_int
    return int(getter())


@dataclass
class RealtimeState:
    """What :func:`apply_realtime` did: applied settings and one-line notes."""

    applied: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def _not_permitted(what: str, exc: OSError) -> str:
    why = exc.strerror or type(exc).__name__
    return (
        f"{what} not permitted ({why}; needs CAP_SYS_NICE or an rtprio/nice limit, "
        "docs/deploy.md): running at normal priority"
    )


def apply_realtime(opts: RealtimeOptions, pid: int = 0) -> RealtimeState:
    """Apply affinity, priority and (this process only) OpenBLAS's thread count; never raises on EPERM.

    A setting the OS refuses (no permission, a core that does not exist, a platform
    without the call) is skipped and named in one line of ``notes``; ``applied``
    holds what took effect. The GC and onnxruntime's threads are applied by
    :func:`frozen_gc` and :func:`pinned_session`.
    """
    state = RealtimeState()
    if opts.pin_threads and pid == 0:
        got = blas_threads(1)
        if got is None:
            state.notes.append(
                "--pin-threads: no OpenBLAS found; numpy's BLAS threads left as they are"
            )
        else:
            state.applied["blas_threads"] = got
    if opts.cpus is not None:
        if not hasattr(os, "sched_setaffinity"):
            state.notes.append("--cpus: CPU affinity is not available on this platform")
        else:
            try:
                os.sched_setaffinity(pid, opts.cpus)
                state.applied["cpus"] = sorted(os.sched_getaffinity(pid))
            except OSError as exc:
                state.notes.append(
                    f"--cpus {','.join(map(str, opts.cpus))}: not applied "
                    f"({exc.strerror or exc}; cores available: "
                    f"{','.join(map(str, sorted(os.sched_getaffinity(pid))))})"
                )
    if opts.priority == "fifo":
        if not hasattr(os, "sched_setscheduler"):
            state.notes.append(
                "--priority fifo: SCHED_FIFO is not available on this platform"
            )
        else:
            try:
                os.sched_setscheduler(
                    pid, os.SCHED_FIFO, os.sched_param(opts.rt_priority)
                )
                state.applied["priority"] = f"fifo:{opts.rt_priority}"
            except OSError as exc:
                state.notes.append(
                    _not_permitted(f"--priority fifo:{opts.rt_priority}", exc)
                )
    elif opts.priority == "nice":
        try:
            if pid == 0:
                new = os.nice(opts.nice)
            else:
                new = os.getpriority(os.PRIO_PROCESS, pid) + opts.nice
                os.setpriority(os.PRIO_PROCESS, pid, new)
            state.applied["priority"] = f"nice:{new}"
        except OSError as exc:
            state.notes.append(_not_permitted(f"--priority nice:{opts.nice}", exc))
    return state


@contextlib.contextmanager
def frozen_gc(enabled: bool = True) -> Iterator[None]:
    """Collect, freeze and disable the garbage collector for the block (restored after).

    ``enabled=False`` is a no-op, so callers need no branch.
    """
    if not enabled:
        yield
        return
    was_enabled = gc.isenabled()
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        gc.unfreeze()
        if was_enabled:
            gc.enable()


def pinned_session(spec: SessionSpec, opts: RealtimeOptions) -> SessionSpec:
    """``spec`` with one intra-op and one inter-op thread (and the spinning choice) when
    ``opts.pin_threads``; ``spec`` unchanged otherwise."""
    if not opts.pin_threads:
        return spec
    return replace(
        spec,
        intra_op_num_threads=1,
        inter_op_num_threads=1,
        allow_spinning=bool(opts.allow_spinning),
    )


__all__ = [
    "DEFAULT_NICE",
    "DEFAULT_RT_PRIORITY",
    "PRIORITIES",
    "RealtimeOptions",
    "RealtimeState",
    "apply_realtime",
    "blas_threads",
    "frozen_gc",
    "options_from_text",
    "parse_cpus",
    "parse_priority",
    "pinned_session",
]
