"""The streaming decision loop: ring buffer -> preprocessing -> one onnxruntime call -> rule -> debounce.

Per frame, :meth:`StreamLoop.step` copies the frame into a preallocated ring buffer;
once a window is full and on every ``hop``-th frame it runs the bundle's
preprocessing, writes the result into a preallocated graph input, calls the session
once for the score output only, applies the decision rule (``score >= threshold``, with
the class order and strictness of :class:`~slipkit.runtime.bundle.DecisionSpec`, or
``argmax == positive``) and the debounce (slip is *declared* on the ``k``-th
consecutive slip decision, as :func:`slipkit.models.online.debounce` does offline).
Latency runs from the frame's arrival (``time.perf_counter_ns`` taken by the source)
to the declared decision, so it includes buffering and preprocessing; writing the
record into the result arrays comes after the clock stops.

Ring buffer
-----------
Each frame is written twice, at slot ``i`` and ``i + window`` of a ``2 * window``
buffer, so the latest window is always the contiguous slice ``ring[j : j + window]``
(oldest frame first): O(1) per frame and no copy to hand the window to numpy or
onnxruntime. (``collections.deque`` or ``np.roll`` would cost a copy of the whole
window per frame.)
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import onnxruntime as ort
from numpy.typing import ArrayLike, NDArray

from slipkit.runtime.bundle import Budget, Bundle
from slipkit.runtime.sources import Frame


@dataclass(frozen=True)
class LoopResult:
    """Every decision the loop made, one entry per model call.

    Attributes
    ----------
    frame : ndarray of int64
        Stream position (0-based count of frames pushed) of the frame that completed
        the window.
    timestamp : ndarray of float64
        That frame's sensor time, s.
    score : ndarray of float64
        The score the rule read (``argmax``: the positive class's entry).
    slip : ndarray of bool
        Per-call decision before debounce.
    declared : ndarray of bool
        Slip declared (``k`` consecutive slip decisions ending here).
    latency_ns : ndarray of int64
        Frame arrival to decision, ns.
    n_frames : int
        Frames pushed (including those that only filled the window or fell between hops).
    name : str
        Bundle name.
    debounce_k : int
        The debounce ``k``.
    budget : Budget
        The bundle's latency budget.
    """

    frame: NDArray[np.int64]
    timestamp: NDArray[np.float64]
    score: NDArray[np.float64]
    slip: NDArray[np.bool_]
    declared: NDArray[np.bool_]
    latency_ns: NDArray[np.int64]
    n_frames: int
    name: str
    debounce_k: int
    budget: Budget

    def summary(self) -> dict[str, Any]:
        """Counts and latency percentiles, ms, against the budget (JSON-ready)."""
        return {
            "bundle": self.name,
            "frames": self.n_frames,
            "decisions": len(self.slip),
            "slip_decisions": int(self.slip.sum()),
            "declared": int(self.declared.sum()),
            "debounce_k": self.debounce_k,
            "first_declared_s": (
                float(self.timestamp[self.declared][0]) if self.declared.any() else None
            ),
            **latency_summary(self.latency_ns, self.budget),
        }


def latency_summary(latency_ns: ArrayLike, budget: Budget) -> dict[str, Any]:
    """p50 / p99 / max / mean latency, ms, and the frames over the p99 budget and the period.

    ``within_budget`` is ``p99 <= budget.p99_ms`` (None without decisions).
    """
    lat_ms = np.asarray(latency_ns, dtype=np.float64) / 1e6
    out: dict[str, Any] = {
        "budget_ms": {"p99": budget.p99_ms, "frame_period": budget.frame_period_ms},
    }
    if len(lat_ms) == 0:
        out.update(latency_ms=None, over_budget=0, over_period=0, within_budget=None)
        return out
    p50, p99 = np.percentile(lat_ms, [50, 99])
    out.update(
        latency_ms={
            "p50": float(p50),
            "p99": float(p99),
            "max": float(lat_ms.max()),
            "mean": float(lat_ms.mean()),
        },
        over_budget=int(np.sum(lat_ms > budget.p99_ms)),
        over_period=int(np.sum(lat_ms > budget.frame_period_ms)),
        within_budget=bool(p99 <= budget.p99_ms),
    )
    return out


class StreamLoop:
    """Decide slip frame by frame with a bundle's session.

    Parameters
    ----------
    bundle : Bundle
        A loaded bundle (:func:`slipkit.runtime.load_bundle`).
    io_binding : bool
        Run through an onnxruntime IOBinding with the input and the score output
        bound once to preallocated arrays (default), instead of ``session.run``
        (which builds a feed, allocates its output and returns a list each call).
        ``benchmarks/bench_runtime_loop.py`` measures both side by side: the
        binding saved about 1.4 us per call on this machine (``docs/deploy.md``).
    capacity : int
        Initial number of decision records (grows by doubling).

    Attributes
    ----------
    n_frames : int
        Frames pushed since construction or :meth:`reset`.
    """

    def __init__(
        self, bundle: Bundle, *, io_binding: bool = True, capacity: int = 1024
    ) -> None:
        m = bundle.manifest
        self.bundle = bundle
        self._w = m.frame.window
        self._hop = m.frame.hop
        self._k = m.debounce_k
        self._ring = np.zeros((2 * self._w, *m.frame.shape))
        self._windows = [self._ring[j : j + self._w] for j in range(self._w)]
        self._ops = list(bundle.preprocessing.ops)
        (inp,) = m.inputs
        assert inp.shape is not None
        assert inp.dtype is not None
        self._input = np.zeros(inp.shape, dtype=np.dtype(inp.dtype))
        # The graph input seen in the preprocessing's output shape (same values, a
        # view): writing the window into it needs no reshape per frame.
        self._input_view = self._input.reshape(bundle.preprocessing.out_shape)
        self._feed = {inp.name: self._input}
        d = m.decision
        self._out_names = [d.output]
        self._argmax = d.rule == "argmax"
        self._col = d.column
        self._thr = -math.inf if d.threshold is None else d.threshold
        self._strict = d.strict
        self._slip_above = d.slip_above
        self._session = bundle.session
        self._binding: ort.IOBinding | None = None
        probe = np.asarray(self._session.run(self._out_names, self._feed)[0])
        if io_binding:
            self._out = np.empty_like(probe)
            self._binding = self._session.io_binding()
            # ortvalue_from_numpy shares the numpy buffer on the CPU: rewriting
            # self._input in place is what the next call sees, and the score lands
            # in self._out without an allocation.
            self._in_ort = ort.OrtValue.ortvalue_from_numpy(self._input)
            self._out_ort = ort.OrtValue.ortvalue_from_numpy(self._out)
            self._binding.bind_ortvalue_input(inp.name, self._in_ort)
            self._binding.bind_ortvalue_output(d.output, self._out_ort)
        for _ in range(bundle.session_spec.warmup):
            self._call()
        self._capacity = capacity
        self.reset()

    def reset(self) -> None:
        """Forget the window, the debounce state and the records."""
        self._ring[...] = 0.0
        self._pos = 0
        self.n_frames = 0
        self._run = 0
        self._n = 0
        cap = self._capacity
        self._frame = np.zeros(cap, dtype=np.int64)
        self._ts = np.zeros(cap)
        self._score = np.zeros(cap)
        self._slip = np.zeros(cap, dtype=bool)
        self._decl = np.zeros(cap, dtype=bool)
        self._lat = np.zeros(cap, dtype=np.int64)

    def window(self) -> NDArray[np.float64]:
        """A copy of the latest ``window`` frames, oldest first (zeros before they arrive)."""
        return self._windows[self._pos].copy()

    def _call(self) -> NDArray[Any]:
        if self._binding is None:
            out: NDArray[Any] = self._session.run(self._out_names, self._feed)[0]
            return out
        self._session.run_with_iobinding(self._binding)
        return self._out

    def _grow(self) -> None:
        for name in ("_frame", "_ts", "_score", "_slip", "_decl", "_lat"):
            old = getattr(self, name)
            new = np.zeros(2 * len(old), dtype=old.dtype)
            new[: len(old)] = old
            setattr(self, name, new)

    def step(
        self,
        values: ArrayLike,
        timestamp: float = math.nan,
        arrival_ns: int | None = None,
    ) -> bool | None:
        """Push one frame; decide when a window is complete and the hop is due.

        Parameters
        ----------
        values : array_like of shape frame.shape
            The frame, in the manifest's channel order.
        timestamp : float
            Its sensor time, s (recorded with the decision).
        arrival_ns : int, optional
            :func:`time.perf_counter_ns` at arrival; now when omitted.

        Returns
        -------
        bool or None
            Whether slip is declared (debounced) on this frame; None when no
            decision was made (window still filling, or between hops).
        """
        t0 = time.perf_counter_ns() if arrival_ns is None else arrival_ns
        w = self._w
        p = self._pos
        ring = self._ring
        ring[p] = values
        ring[p + w] = values
        p += 1
        if p == w:
            p = 0
        self._pos = p
        seen = self.n_frames = self.n_frames + 1
        if seen < w or (seen - w) % self._hop:
            return None
        x = self._windows[p]
        for op in self._ops:
            x = op(x)
        self._input_view[...] = x
        if self._binding is None:
            score = self._session.run(self._out_names, self._feed)[0]
        else:
            self._session.run_with_iobinding(self._binding)
            score = self._out
        s = float(score.flat[self._col])
        if self._argmax:
            slip = int(score.argmax()) == self._col
        else:
            above = s > self._thr if self._strict else s >= self._thr
            slip = above == self._slip_above
        run = self._run = self._run + 1 if slip else 0
        declared = run >= self._k
        t1 = time.perf_counter_ns()
        i = self._n
        if i == len(self._lat):
            self._grow()
        self._frame[i] = seen - 1
        self._ts[i] = timestamp
        self._score[i] = s
        self._slip[i] = slip
        self._decl[i] = declared
        self._lat[i] = t1 - t0
        self._n = i + 1
        return declared

    def run(self, source: Iterable[Frame]) -> LoopResult:
        """Push every frame of a source (replay or UDP) and return the result."""
        step = self.step
        for frame in source:
            step(frame.values, frame.timestamp, frame.arrival_ns)
        return self.result()

    def result(self) -> LoopResult:
        """The decisions so far (copies)."""
        n = self._n
        m = self.bundle.manifest
        return LoopResult(
            frame=self._frame[:n].copy(),
            timestamp=self._ts[:n].copy(),
            score=self._score[:n].copy(),
            slip=self._slip[:n].copy(),
            declared=self._decl[:n].copy(),
            latency_ns=self._lat[:n].copy(),
            n_frames=self.n_frames,
            name=m.name,
            debounce_k=m.debounce_k,
            budget=m.budget,
        )
