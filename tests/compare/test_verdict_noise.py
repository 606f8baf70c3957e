"""The deploy verdict under injected timing noise: a seeded fake clock, no wall clock."""

from __future__ import annotations

import numpy as np
import pandas as pd

from slipkit.compare.table import choose_deploy, seed_table

BUDGET_US = 50.0
SEEDS = (0, 1, 2)
#: (estimator, mean score, idle-machine p99 as a fraction of the budget)
ROWS = (
    ("heavy", 0.95, 3.0),  # far over: never recommended
    ("edge", 0.90, 0.9),  # near: borderline, the verdict
    ("light", 0.70, 0.2),  # far within: the fallback a flip would land on
)


class FakeClock:
    """A seeded stand-in for ``time.perf_counter_ns`` on a shared machine.

    Each frame arrives one period after the last; its work takes a lognormal time
    (median ``median_us``), times a load factor of the whole run (a busy machine only
    slows: 1 + an exponential slowdown) and, rarely, a scheduler stall of 5 ms.
    """

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.now_ns = 0
        self.load = 1.0 + rng.exponential(0.05)

    def perf_counter_ns(self) -> int:
        return self.now_ns

    def work(self, median_us: float) -> None:
        us = median_us * self.load * self.rng.lognormal(0.0, 0.25)
        if self.rng.random() < 0.002:
            us += 5000.0
        self.now_ns += int(us * 1e3)

    def latencies_us(
        self, median_us: float, frames: int, period_us: float
    ) -> np.ndarray:
        out = np.empty(frames)
        for i in range(frames):
            self.now_ns = int(i * period_us * 1e3)  # the frame's arrival
            t0 = self.perf_counter_ns()
            self.work(median_us)
            out[i] = (self.perf_counter_ns() - t0) / 1e3
        return out


def _verdict(draw: int) -> tuple[str, bool, bool]:
    """One comparison of three seeds, its frames timed on a fake clock seeded by ``draw``."""
    rng = np.random.default_rng(draw)
    per_seed, lat = [], {}
    # lognormal(0, 0.25): p99 = median x exp(2.326 x 0.25)
    to_median = float(np.exp(-2.326 * 0.25))
    for est, score, frac in ROWS:
        pooled = []
        for seed in SEEDS:
            clock = FakeClock(rng)
            pooled.append(clock.latencies_us(BUDGET_US * frac * to_median, 600, 500.0))
            per_seed.append(
                {
                    "estimator": est,
                    "kind": "learned",
                    "class": "X",
                    "balanced_accuracy": score,
                    "budget_p99_us": BUDGET_US,
                    "export": "ok",
                    "seed": seed,
                }
            )
        lat[est] = np.concatenate(pooled)
    choice = choose_deploy(seed_table(pd.DataFrame(per_seed), lat, "balanced_accuracy"))
    assert choice.row is not None
    return str(choice.row["estimator"]), choice.recommended, choice.borderline


def test_verdict_does_not_flip_under_timing_noise() -> None:
    """Across 50 noise draws (jitter, load, stalls) the verdict is the row at 0.9 x the
    budget every time, recommended and flagged borderline, never passed over as over."""
    verdicts = {_verdict(draw) for draw in range(50)}
    assert {("edge", True, True)} == verdicts
