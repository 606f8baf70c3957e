"""Choose session options by measuring the loop on a bundle's own recorded frames.

Exporters call :func:`choose_session` and write the winner into the manifest's
``session`` (``slipkit-run <bundle> --choose-session`` prints the same table). The
candidates are measured round-robin for several rounds and each candidate's median
over rounds is kept, so a burst of load from other processes does not single out
one candidate. Ranked by p99 (the budget's statistic), then p50.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slipkit.runtime.bundle import Bundle
from slipkit.runtime.errors import OptionError
from slipkit.runtime.loop import StreamLoop
from slipkit.runtime.session import SessionSpec

#: Most round-robin passes :func:`choose_session` runs.
MAX_ROUNDS = 100


def default_candidates(warmup: int = 20) -> list[SessionSpec]:
    """Threads 1 and 2 x graph optimisation basic/extended/all x spinning (2 threads only).

    Spinning only changes anything with a second intra-op thread, so one-thread
    candidates are measured without it.
    """
    out = []
    for threads, level in itertools.product((1, 2), ("basic", "extended", "all")):
        for spin in (False, True) if threads > 1 else (False,):
            out.append(
                SessionSpec(
                    intra_op_num_threads=threads,
                    graph_optimization_level=level,
                    allow_spinning=spin,
                    warmup=warmup,
                )
            )
    return out


def choose_session(
    bundle: Bundle,
    frames: NDArray[np.floating],
    timestamps: NDArray[np.float64],
    *,
    candidates: list[SessionSpec] | None = None,
    rounds: int = 3,
    max_frames: int = 500,
    io_binding: bool = True,
) -> list[dict[str, Any]]:
    """Measure the full loop under each session option set.

    Parameters
    ----------
    bundle : Bundle
        The loaded bundle.
    frames, timestamps : ndarray
        Recorded frames ``(n, *frame.shape)`` and times (s), e.g. ``replay.npz``.
    candidates : list of SessionSpec, optional
        Option sets; :func:`default_candidates` by default.
    rounds : int
        Round-robin passes; each candidate's p50/p99 is its median over rounds.
    max_frames : int
        Frames replayed per pass (the first ones).
    io_binding : bool
        Measure the IOBinding path of :class:`StreamLoop`.

    Returns
    -------
    list of dict
        ``{"session": <manifest session object>, "p50_ms": ..., "p99_ms": ...}``,
        fastest first; empty when the frames make no decision (fewer than a window).

    Raises
    ------
    OptionError
        ``rounds`` outside [1, :data:`MAX_ROUNDS`] or ``max_frames`` below 1.
    """
    if (
        isinstance(rounds, bool)
        or not isinstance(rounds, int)
        or not 1 <= rounds <= MAX_ROUNDS
    ):
        raise OptionError(
            "rounds", f"must be an integer in [1, {MAX_ROUNDS}]; got {rounds!r}"
        )
    if (
        isinstance(max_frames, bool)
        or not isinstance(max_frames, int)
        or max_frames < 1
    ):
        raise OptionError("max_frames", f"must be an integer >= 1; got {max_frames!r}")
    specs = (
        default_candidates(bundle.session_spec.warmup)
        if candidates is None
        else candidates
    )
    loops = [StreamLoop(bundle.with_session(s), io_binding=io_binding) for s in specs]
    frames, timestamps = frames[:max_frames], timestamps[:max_frames]
    stats: list[list[tuple[float, float]]] = [[] for _ in specs]
    for _ in range(rounds):
        for i, loop in enumerate(loops):
            loop.reset()
            step = loop.step
            for values, ts in zip(frames, timestamps.tolist(), strict=True):
                step(values, ts)
            lat = loop.result().latency_ns / 1e6
            if len(lat):
                p50, p99 = np.percentile(lat, [50, 99])
                stats[i].append((float(p50), float(p99)))
    rows = []
    for spec, st in zip(specs, stats, strict=True):
        if not st:
            continue
        arr = np.asarray(st)
        rows.append(
            {
                "session": spec.to_json(),
                "p50_ms": float(np.median(arr[:, 0])),
                "p99_ms": float(np.median(arr[:, 1])),
            }
        )
    rows.sort(key=lambda r: (r["p99_ms"], r["p50_ms"]))
    return rows
