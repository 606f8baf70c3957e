"""What a run of the runtime loop returns: every decision and its latency
(:class:`LoopResult`), and the latency summary judged against the sensor's budget."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slipkit.runtime.budget import frame_latency_us, judge_latency
from slipkit.runtime.bundle import Budget

#: Why a frame was flagged (see :mod:`slipkit.runtime.loop`), in the order they are checked.
BAD_REASONS = (
    "dtype",
    "shape",
    "nonfinite",
    "timestamp",
    "duplicate_time",
    "time_order",
)


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
        The score the rule read (``argmax``: the largest slip-class entry).
    slip : ndarray of bool
        Per-call decision before debounce.
    klass : ndarray of int64
        Per-call decided class, an index into ``classes`` (``argmax``: the largest
        entry; ``threshold``: 1 above, 0 below); -1 when the bundle names no classes.
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
    bad_frame : ndarray of int64
        Stream positions of the flagged frames, in order.
    bad_reason : tuple of str
        Why each was flagged (one of :data:`BAD_REASONS`).
    skipped_windows : int
        Windows due for a decision but not scored: they held a flagged frame,
        spanned a gap (``skip_gaps``), or their graph input or score was not finite.
    nonfinite_windows : int
        Of those, windows whose graph input or score came out NaN or infinite.
    gaps : int
        Timestamps more than ``max_gap_periods`` frame periods after the previous one.
    classes : tuple of str or None
        The decision's class names (None: an unclassed threshold on a regressor).
    slip_classes : tuple of str
        The classes that count as slip.
    state_resets : int
        Times a stateful bundle's recurrent state was set back to zeros (a flagged
        frame, a gap, a non-finite window; module docstring, *Recurrent state*);
        0 without state.
    prepare_latency_ns : ndarray of int64
        A bundle with a prepare graph: arrival to the end of the prepare call, ns, of
        each frame that ran it (module docstring, *Prepared decisions*); empty
        without one.
    prepare_late : int
        Decisions whose prepare graph ran on the decision frame itself.
    has_prepare : bool
        The bundle has a prepare graph.
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
    bad_frame: NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64)
    )
    bad_reason: tuple[str, ...] = ()
    skipped_windows: int = 0
    nonfinite_windows: int = 0
    gaps: int = 0
    klass: NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64)
    )
    classes: tuple[str, ...] | None = None
    slip_classes: tuple[str, ...] = ()
    state_resets: int = 0
    prepare_latency_ns: NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64)
    )
    prepare_late: int = 0
    has_prepare: bool = False

    def class_counts(self) -> dict[str, int] | None:
        """Decisions per class, in class order (None when the bundle names no classes)."""
        if self.classes is None:
            return None
        counts = np.bincount(
            self.klass[self.klass >= 0], minlength=len(self.classes)
        ).tolist()
        return {c: int(n) for c, n in zip(self.classes, counts, strict=False)}

    def bad_counts(self) -> dict[str, int]:
        """Flagged frames per reason (every reason of :data:`BAD_REASONS`, zeros included)."""
        counts = dict.fromkeys(BAD_REASONS, 0)
        for reason in self.bad_reason:
            counts[reason] += 1
        return counts

    def summary(self, paced: bool | None = None) -> dict[str, Any]:
        """Counts and latency percentiles, ms, against the budget (JSON-ready).

        ``decisions`` counts the valid (scored) windows, ``decisions_by_class`` the
        decided class of each (None without classes) and ``slip_decisions`` those
        whose class is one of ``slip_classes``; ``bad_frames``,
        ``bad_by_reason``, ``skipped_windows``, ``nonfinite_windows`` and ``gaps`` count
        what the loop flagged (module docstring, *Bad frames*); ``state_resets``
        the times a recurrent state was zeroed (*Recurrent state*). With a prepare
        graph, ``prepare`` holds its frames' latency (``calls``, ``late``, and
        :func:`latency_summary`'s fields; None without a prepare graph).
        ``latency_check`` is the latency rule's judgement of the decision and prepare
        frames pooled (:func:`slipkit.runtime.budget.judge_latency`; ``paced`` says
        whether the frames were paced) and ``within_budget`` its ``passed`` (None
        without decisions).
        """
        out = {
            "bundle": self.name,
            "frames": self.n_frames,
            "bad_frames": len(self.bad_reason),
            "bad_by_reason": self.bad_counts(),
            "skipped_windows": self.skipped_windows,
            "nonfinite_windows": self.nonfinite_windows,
            "gaps": self.gaps,
            "state_resets": self.state_resets,
            "decisions": len(self.slip),
            "decisions_by_class": self.class_counts(),
            "slip_classes": list(self.slip_classes),
            "slip_decisions": int(self.slip.sum()),
            "declared": int(self.declared.sum()),
            "debounce_k": self.debounce_k,
            "first_declared_s": (
                float(self.timestamp[self.declared][0]) if self.declared.any() else None
            ),
            **latency_summary(self.latency_ns, self.budget),
            "prepare": None,
        }
        if self.has_prepare:
            prep = latency_summary(self.prepare_latency_ns, self.budget)
            prep.pop("budget_ms")
            out["prepare"] = {
                "calls": len(self.prepare_latency_ns),
                "late": self.prepare_late,
                **prep,
            }
        check = judge_latency(
            frame_latency_us(self), self.budget.p99_ms * 1e3, paced=paced
        )
        out["latency_check"] = check.to_json()
        out["within_budget"] = None if not len(self.slip) else check.passed
        return out


def latency_summary(latency_ns: ArrayLike, budget: Budget) -> dict[str, Any]:
    """p50 / p99 / max / mean latency, ms, and the frames over the p99 budget and the period.

    ``within_budget`` is the latency rule's ``passed`` on these latencies
    (:func:`slipkit.runtime.budget.judge_latency`; None without decisions); ``p99``
    is the plain p99, shown beside the judged one.
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
        within_budget=judge_latency(lat_ms * 1e3, budget.p99_ms * 1e3).passed,
    )
    return out
