"""The latency rule: one pacing, one statistic and one margin, for every budget verdict.

``slipkit compare`` (its cost step and its verdict), the demo's replay and
``slipkit-run --check`` all judge a bundle's latency with this module, so a bundle the
verdict recommends passes ``--check`` on the same machine.

Pacing
    Replayed frames are released at their own timestamps (the sensor's rate), as a live
    sensor delivers them: a loop that sleeps between frames wakes with cold caches, and
    an unpaced replay (frames back to back) understates a live loop's latency several
    times. A paced replay of ``n`` frames takes ``n / rate_hz`` seconds, so it is capped
    at :func:`paced_frames`: at most ``max(PACED_MIN_FRAMES, PACED_S * rate_hz)`` frames.
    A sensor whose frame period is under :data:`SPIN_BELOW_MS` (the 2 kHz FSR) is
    paced by spinning to each frame's due time (:func:`pacing_spins`), as a real-time
    loop at that rate does: a sleep's wake-up alone is a large share of such a budget.
Statistic
    Per-frame latency (arrival -> end of the frame's work) of the decision frames and
    of the prepare frames (bundles with a prepare graph), pooled; the p99 judged is the
    median of the p99s of :data:`P99_BLOCKS` contiguous blocks (:func:`block_p99`), so
    one stall of a shared machine does not decide.
Margin
    ``margin = p99 / budget``: ``within`` up to :data:`BORDERLINE`, ``borderline`` up to
    ``1 / BORDERLINE`` (passes, flagged: a re-measure may land on the other side),
    ``over`` beyond (fails). The budget is already 10 % of the frame period, so the band
    is far from a missed frame. It is per frame whatever the bundle's ``hop``: the loop
    makes a decision within its frame's step, so the frames behind it (in a hand, every
    stream's) wait for it; a call every ``hop`` frames gets no more time.

Standard library and numpy only: it runs on the gripper PC.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: a p99 above this fraction of the budget is borderline; above its inverse, over
BORDERLINE = 0.8
#: contiguous blocks the per-frame latencies are cut into (:func:`block_p99`)
P99_BLOCKS = 5
#: a paced replay's cap: at most this many seconds of frames ...
PACED_S = 3.0
#: ... unless that is fewer than this many frames (a slow sensor)
PACED_MIN_FRAMES = 300
#: a paced replay spins to each frame's due time, instead of sleeping, when the
#: sensor's frame period is under this many milliseconds
SPIN_BELOW_MS = 2.0
#: what a judgement's ``status`` can be
STATUSES = ("within", "borderline", "over", "not measured")
#: what an unpaced replay says about its latency
UNPACED_NOTE = "unpaced: latency understates a live loop"
#: the statistic, as reports name it
STATISTIC = f"median of {P99_BLOCKS} block p99s"
#: the rule in one paragraph (reports print it under a verdict)
RULE_TEXT = (
    "Latency rule (the same for compare, the demo and slipkit-run --check): replay "
    "frames paced at the sensor's rate (spinning to each due time when the frame "
    f"period is under {SPIN_BELOW_MS:g} ms; at most max("
    f"{PACED_MIN_FRAMES} frames, {PACED_S:g} s)); p99 = the {STATISTIC} of the "
    "per-frame latency (decision and prepare frames pooled; all seeds' frames in a "
    f"comparison); within when p99 <= {BORDERLINE:g} x the budget, borderline (passes, "
    f"flagged) up to {1 / BORDERLINE:g} x, over (fails) beyond."
)


def pacing_spins(rate_hz: float) -> bool:
    """Whether a paced replay at ``rate_hz`` spins to each due time (frame period under
    :data:`SPIN_BELOW_MS`) rather than sleeping."""
    return bool(
        math.isfinite(rate_hz) and rate_hz > 0 and 1e3 / rate_hz < SPIN_BELOW_MS
    )


def paced_frames(
    n: int,
    rate_hz: float,
    *,
    paced_s: float = PACED_S,
    min_frames: int = PACED_MIN_FRAMES,
) -> int:
    """How many of ``n`` replay frames a paced replay at ``rate_hz`` plays.

    ``min(n, max(min_frames, ceil(paced_s * rate_hz)))``: about ``paced_s`` seconds of
    frames, never fewer than ``min_frames`` (a slow sensor still gives a p99 of a few
    hundred frames), never more than there are.
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        return int(min(n, min_frames))
    return int(min(n, max(min_frames, math.ceil(paced_s * rate_hz))))


def _blocks(lat: NDArray[np.float64], blocks: int) -> list[NDArray[np.float64]]:
    return list(np.array_split(lat, blocks))


def _finite(latency_us: ArrayLike) -> NDArray[np.float64]:
    lat = np.asarray(latency_us, dtype=np.float64).ravel()
    return lat[np.isfinite(lat)]


def block_p99(latency_us: ArrayLike, blocks: int = P99_BLOCKS) -> float:
    """The p99 the budget is judged on: the median over ``blocks`` contiguous blocks of their p99.

    A plain p99 over a few thousand frames is set by a handful of them; on a shared
    machine one scheduler stall moves it by tens of microseconds, enough to flip a
    verdict near the budget. The median of per-block p99s ignores a stall confined to
    fewer than half of the blocks. With fewer than ``2 * blocks`` latencies the plain
    p99 is returned; NaN without any finite latency (NaNs are dropped).
    """
    lat = _finite(latency_us)
    if len(lat) == 0:
        return math.nan
    if blocks <= 1 or len(lat) < 2 * blocks:
        return float(np.percentile(lat, 99))
    return float(np.median([np.percentile(b, 99) for b in _blocks(lat, blocks)]))


def quiet_p99(latency_us: ArrayLike, blocks: int = P99_BLOCKS) -> float:
    """The lowest of the ``blocks`` contiguous blocks' p99s: the run's quietest stretch.

    Not what the budget is judged on (:func:`block_p99` is): it tells a p99 a loaded
    machine put over the budget (the quietest block meets it) from one the model makes
    itself. As :func:`block_p99` for short or empty input.
    """
    lat = _finite(latency_us)
    if len(lat) == 0:
        return math.nan
    if blocks <= 1 or len(lat) < 2 * blocks:
        return float(np.percentile(lat, 99))
    return float(min(np.percentile(b, 99) for b in _blocks(lat, blocks)))


def pool(*series: ArrayLike) -> NDArray[np.float64]:
    """Several per-frame latency series of one run merged in (approximate) arrival order.

    Each series is in arrival order and spans the whole run (decision frames, prepare
    frames), so its ``i``-th of ``n`` entries is placed at ``(i + 0.5) / n`` of the run
    and the merge sorts on that place (stable): the contiguous blocks of
    :func:`block_p99` then cut every series at the same fractions of the run. (The
    loop records no frame index per prepare call: recording one would cost the hot
    path a store per frame for a statistic.)
    """
    parts = [np.asarray(s, dtype=np.float64).ravel() for s in series]
    parts = [p for p in parts if len(p)]
    if not parts:
        return np.zeros(0)
    if len(parts) == 1:
        return parts[0].copy()
    where = np.concatenate([(np.arange(len(p)) + 0.5) / len(p) for p in parts])
    return np.concatenate(parts)[np.argsort(where, kind="stable")]


class _Result(Protocol):
    """What :func:`frame_latency_us` reads of a :class:`~slipkit.runtime.loop.LoopResult`."""

    @property
    def latency_ns(self) -> Any: ...

    @property
    def prepare_latency_ns(self) -> Any: ...


def frame_latency_us(result: _Result) -> NDArray[np.float64]:
    """A loop result's per-frame latencies, us: decision and prepare frames pooled (:func:`pool`)."""
    return pool(
        np.asarray(result.latency_ns, dtype=np.float64) / 1e3,
        np.asarray(result.prepare_latency_ns, dtype=np.float64) / 1e3,
    )


@dataclass(frozen=True)
class LatencyJudgement:
    """A p99 judged against a budget by the latency rule (module docstring).

    Attributes
    ----------
    p99_us : float
        The judged p99 (:func:`block_p99`), us; NaN when nothing was measured.
    budget_us : float
        The p99 budget, us.
    margin : float
        ``p99_us / budget_us`` (NaN when either is missing).
    status : str
        ``within``, ``borderline``, ``over`` or ``not measured`` (:data:`STATUSES`).
    passed : bool
        True for ``within`` and ``borderline``.
    paced : bool or None
        Whether the frames were paced at the sensor's rate (None: not said).
    n : int
        Latencies the p99 was taken on.
    """

    p99_us: float
    budget_us: float
    margin: float
    status: str
    passed: bool
    paced: bool | None = None
    n: int = 0

    @property
    def borderline(self) -> bool:
        """True when the status is ``borderline``."""
        return self.status == "borderline"

    def text(self) -> str:
        """``p99 41.2 us = 0.82 x the 50 us budget: borderline`` (+ the unpaced note)."""
        if self.status == "not measured":
            out = f"p99 not measured against the {self.budget_us:.4g} us budget"
        else:
            out = (
                f"p99 {self.p99_us:.1f} us = {self.margin:.2f} x the "
                f"{self.budget_us:.4g} us budget: {self.status}"
            )
        return out + (f" ({UNPACED_NOTE})" if self.paced is False else "")

    def to_json(self) -> dict[str, Any]:
        """JSON-ready fields (ms, as the runtime's summaries), the statistic named."""
        return {
            "statistic": STATISTIC,
            "p99_ms": None if math.isnan(self.p99_us) else self.p99_us / 1e3,
            "budget_ms": self.budget_us / 1e3,
            "margin": None if math.isnan(self.margin) else self.margin,
            "status": self.status,
            "passed": self.passed,
            "paced": self.paced,
            "timed_frames": self.n,
        }


def judge_p99(
    p99_us: float, budget_us: float, *, paced: bool | None = None, n: int = 0
) -> LatencyJudgement:
    """An already judged p99 (:func:`block_p99`, us) against ``budget_us`` (the margin rule)."""
    p99, budget = float(p99_us), float(budget_us)
    if not (math.isfinite(p99) and math.isfinite(budget) and budget > 0):
        return LatencyJudgement(
            math.nan if not math.isfinite(p99) else p99,
            budget,
            math.nan,
            "not measured",
            False,
            paced,
            n,
        )
    margin = p99 / budget
    if margin <= BORDERLINE:
        status = "within"
    elif margin <= 1 / BORDERLINE:
        status = "borderline"
    else:
        status = "over"
    return LatencyJudgement(p99, budget, margin, status, status != "over", paced, n)


def judge_latency(
    latency_us: ArrayLike, budget_us: float, *, paced: bool | None = None
) -> LatencyJudgement:
    """Per-frame latencies (us, arrival order) judged against a p99 budget (us): the rule.

    Parameters
    ----------
    latency_us : array_like of float
        Every frame's latency in arrival order (:func:`frame_latency_us`; several runs
        concatenated), us; NaNs are dropped.
    budget_us : float
        The bundle's ``budget_ms.p99`` in us.
    paced : bool or None
        Whether the frames were paced (said in :meth:`LatencyJudgement.text`).
    """
    lat = _finite(latency_us)
    return judge_p99(block_p99(lat), budget_us, paced=paced, n=len(lat))


__all__ = [
    "BORDERLINE",
    "P99_BLOCKS",
    "PACED_MIN_FRAMES",
    "PACED_S",
    "RULE_TEXT",
    "STATISTIC",
    "STATUSES",
    "UNPACED_NOTE",
    "LatencyJudgement",
    "block_p99",
    "frame_latency_us",
    "judge_latency",
    "judge_p99",
    "paced_frames",
    "pool",
    "quiet_p99",
]
