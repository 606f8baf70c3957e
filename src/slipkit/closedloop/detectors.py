"""What decides slip in the loop: an exported bundle through the runtime loop, or a bound.

* :class:`BundleDetector`: the code that runs on the gripper PC -
  :func:`slipkit.runtime.load_bundle` and :meth:`slipkit.runtime.StreamLoop.step`, one
  frame at a time, the bundle's own debounce; the loop's per-decision latency
  (frame arrival -> decision, ns; with a prepare graph also its frames' latency) is
  kept for the compute-per-frame columns.
* :class:`OracleDetector`: reads the plant's true slip state (zero detection delay
  beyond the frame on which the slip starts): the lower bound.
* :class:`NoDetector`: never declares: the upper bound (the retraction goes on).
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path

import numpy as np

from slipkit.closedloop.plant import PlantState


class Detector(ABC):
    """Contract: ``reset()`` per trial, ``decide(state, frame)`` per frame -> declared?

    ``frame`` is a callable that builds the sensor frame of ``state`` (only a detector
    that reads the sensor pays for it).
    """

    name: str = "detector"
    kind: str = "bound"
    #: The sensor channels the detector reads, in order (None: it reads no frame).
    channels: tuple[str, ...] | None = None
    #: Its frame rate, Hz (None: every plant frame).
    rate_hz: float | None = None

    def reset(self) -> None:  # noqa: B027 - a bound detector keeps no state
        """Start a new trial (nothing to forget by default)."""

    @abstractmethod
    def decide(self, state: PlantState, frame: Callable[[], np.ndarray]) -> bool:
        """Whether slip is declared on this frame."""

    def latency_us(self) -> np.ndarray:
        """Per-decision compute latencies so far, us (empty for the bounds)."""
        return np.zeros(0)


class OracleDetector(Detector):
    """Declares slip on every frame at least ``delay_s`` into a slide of the plant.

    With ``delay_s = 0`` (the bound) that is every frame on which the object is
    sliding; a positive ``delay_s`` traces the plant's slip distance against a known
    detection delay. (A one-shot controller consults it only up to the first
    declaration; a continuous one, on every slide.)
    """

    def __init__(self, name: str = "oracle", *, delay_s: float = 0.0) -> None:
        self.name = name
        self.delay_s = float(delay_s)
        if not (math.isfinite(self.delay_s) and self.delay_s >= 0):
            raise ValueError(f"delay_s must be a finite number >= 0 s; got {delay_s!r}")

    def decide(self, state: PlantState, frame: Callable[[], np.ndarray]) -> bool:
        """True while the plant slides and its slide has lasted ``delay_s``."""
        del frame
        # 1e-9 s: a delay of a whole number of frames lands on that frame.
        return state.sliding and state.t - state.slide_start_s >= self.delay_s - 1e-9


class NoDetector(Detector):
    """Never declares slip."""

    def __init__(self, name: str = "none") -> None:
        self.name = name

    def decide(self, state: PlantState, frame: Callable[[], np.ndarray]) -> bool:
        """Always False."""
        del state, frame
        return False


class BundleDetector(Detector):
    """An exported bundle deciding frame by frame through :class:`~slipkit.runtime.StreamLoop`.

    Parameters
    ----------
    bundle_dir : Path
        A bundle folder (``slipkit export``).
    name : str
        Row name in the table.
    warmup : int
        Session warm-up calls before the first frame.

    Attributes
    ----------
    debounce_k : int
        The bundle's debounce (consecutive slip decisions).
    p99_budget_us, frame_period_us : float
        The sensor's budget from the manifest, us.
    channels : tuple of str
        The frame's channels, in order (``stream.channel`` when the frame spans
        several streams, else the channel).
    rate_hz : float
        The frame rate, Hz.
    """

    kind = "bundle"

    def __init__(self, bundle_dir: Path, name: str, *, warmup: int = 20) -> None:
        from slipkit.runtime import SessionSpec, StreamLoop, load_bundle

        spec = SessionSpec(
            intra_op_num_threads=1,
            inter_op_num_threads=1,
            graph_optimization_level="all",
            allow_spinning=False,
            warmup=int(warmup),
        )
        self.bundle = load_bundle(bundle_dir, session=spec)
        self.name = name
        m = self.bundle.manifest
        self.debounce_k = int(m.debounce_k)
        self.p99_budget_us = float(m.budget.p99_ms) * 1e3
        self.frame_period_us = float(m.budget.frame_period_ms) * 1e3
        self.channels = tuple(str(c) for c in m.frame.channels)
        self.rate_hz = float(m.frame.rate_hz)
        self.loop = StreamLoop(self.bundle)
        self._lat: list[np.ndarray] = []

    def _collect(self) -> None:
        # Every frame that ran a graph: the decisions and, for a bundle with a prepare
        # graph (SlipTack), the frames before them, which carry the prepare call
        # (docs/deploy.md, "Prepared decisions"): the compute per frame either way.
        res = self.loop.result()
        lat = np.concatenate([res.latency_ns, res.prepare_latency_ns])
        if len(lat):
            self._lat.append(np.asarray(lat, dtype=np.float64) / 1e3)

    def reset(self) -> None:
        """Keep the finished trial's latencies, then clear the window and the debounce."""
        self._collect()
        self.loop.reset()

    def decide(self, state: PlantState, frame: Callable[[], np.ndarray]) -> bool:
        """Push the frame of ``state`` into the loop; True when the loop declares slip."""
        values = frame()
        # The clock starts when the frame exists (the camera delivered it).
        return self.loop.step(values, state.t, time.perf_counter_ns()) is True

    def latency_us(self) -> np.ndarray:
        """Every decision's latency so far (this trial's included; with a prepare graph
        the prepare frames' too), us."""
        self._collect()
        out = np.concatenate(self._lat) if self._lat else np.zeros(0)
        self._lat = [out] if len(out) else []
        self.loop.reset()
        return out
