"""What an estimator costs: fit / calibration wall time and compute per frame when deployed.

Compute per frame is measured in the deployment form, not in Python: the run is
exported to a bundle (:func:`slipkit.export.commands.export_main`, into a temporary
folder unless kept), the bundle is loaded by the runtime with a one-thread session
(:class:`slipkit.runtime.SessionSpec`, ``intra_op_num_threads=1``, warm-up calls
first), and its own replay frames (held-out test trials) go through
:class:`slipkit.runtime.StreamLoop` one frame at a time (batch 1), paced at the
sensor's rate and judged by the latency rule (:mod:`slipkit.runtime.budget`, the same
as ``slipkit-run --check``'s): the latency of every decision and prepare frame (frame
arrival -> decision: the preprocessing, the ONNX call and the debounce) gives p50 and
the judged p99 in microseconds against the sensor's budget (the bundle's
``budget_ms``: ``configs/deploy``). A bundle whose paced p99 is not within the
budget is replayed once more back to back (unpaced, the same frames): its p99 there
tells a graph too slow on its own from calls that pay for the idle time before them
(cold caches: a bundle called every ``hop`` frames idles ``hop - 1`` frame periods
between calls). That second p99 is a diagnosis only; the verdict judges the paced one.

An estimator without an exporter, or a task without a deployer, is not an error
here: its cost row says why it could not be exported.
"""

from __future__ import annotations

import contextlib
import functools
import io
import logging
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import OmegaConf

from slipkit.runtime.budget import (
    LatencyJudgement,
    block_p99,
    frame_latency_us,
    judge_p99,
    paced_frames,
    pacing_spins,
)


@dataclass
class FitTimer:
    """Wall time of every ``fit`` call of one estimator class while :meth:`patch` is active.

    Attributes
    ----------
    calls : list of float
        Seconds of each ``fit`` call, in order (clones fitted by a task count too).
    """

    calls: list[float] = field(default_factory=list)

    @contextlib.contextmanager
    def patch(self, cls: type) -> Iterator[FitTimer]:
        """Time ``cls.fit`` for the duration of the block, then restore it.

        The task builds and clones the estimator itself (``slipkit train`` does), so
        the class method is wrapped rather than the instance: every clone is timed.
        """
        own = "fit" in cls.__dict__
        original = cls.__dict__["fit"] if own else None
        inherited = cls.fit  # type: ignore[attr-defined]

        def timed(est: Any, *args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return inherited(est, *args, **kwargs)
            finally:
                self.calls.append(time.perf_counter() - start)

        # update_wrapper sets __wrapped__: inspect.signature(est.fit) still shows the
        # real parameters (a task passes groups= only to a fit that takes them).
        functools.update_wrapper(timed, inherited)
        cls.fit = timed  # type: ignore[attr-defined]
        try:
            yield self
        finally:
            if own:
                cls.fit = original  # type: ignore[attr-defined]
            else:
                delattr(cls, "fit")

    @property
    def total_s(self) -> float:
        """Seconds of all fits the task made (search CV fits and window-sweep refits included), NaN if none."""
        return float(sum(self.calls)) if self.calls else math.nan


@dataclass
class DeployCost:
    """The deployed form's cost: per-decision latency through the runtime loop.

    Attributes
    ----------
    exported : bool
        Whether a bundle was written and loaded.
    note : str
        ``"ok"`` or why the estimator could not be exported / timed.
    latency_us : ndarray
        Frame arrival to the end of its work of every timed decision and prepare
        frame, us (:func:`slipkit.runtime.budget.frame_latency_us`).
    p50_us, p99_us : float
        p50 and the judged p99 (:func:`slipkit.runtime.budget.block_p99`) of
        ``latency_us`` (NaN when not exported).
    budget_p99_us, frame_period_us : float
        The sensor's budget (from the bundle manifest), us.
    bundle : Path or None
        The kept bundle folder (None when it lived in a temporary folder).
    window, hop : int
        Frames per model call and frames between calls in the bundle.
    paced : bool
        Whether the frames were paced at the sensor's rate.
    unpaced_latency_us : ndarray
        The same frames replayed back to back, us (:func:`time_bundle` measures them
        only when the paced p99 is not within the budget; empty otherwise).
    """

    exported: bool
    note: str
    latency_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    p50_us: float = math.nan
    p99_us: float = math.nan
    budget_p99_us: float = math.nan
    frame_period_us: float = math.nan
    bundle: Path | None = None
    window: int = 0
    hop: int = 0
    paced: bool = True
    unpaced_latency_us: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def p99_unpaced_us(self) -> float:
        """The latency rule's p99 of :attr:`unpaced_latency_us` (NaN when not measured)."""
        return block_p99(self.unpaced_latency_us)

    @property
    def judgement(self) -> LatencyJudgement:
        """``p99_us`` against the budget by the latency rule."""
        return judge_p99(
            self.p99_us, self.budget_p99_us, paced=self.paced, n=len(self.latency_us)
        )

    @property
    def within_budget(self) -> bool | None:
        """The latency rule's ``passed`` (within or borderline; None when not measured)."""
        if not self.exported or not math.isfinite(self.p99_us):
            return None
        return self.judgement.passed


@contextlib.contextmanager
def quiet_console() -> Iterator[None]:
    """Keep ``slipkit.*`` log records off the console (Hydra's root handler) for a block.

    Each run's ``train.log`` (a handler on the ``slipkit`` logger itself) still
    receives them; a comparison of many runs would otherwise flood the terminal.
    """
    logger = logging.getLogger("slipkit")
    saved = logger.propagate
    logger.propagate = False
    try:
        yield
    finally:
        logger.propagate = saved


def export_run(run: Path, out: Path, *, max_frames: int) -> Path:
    """Export the run folder ``run`` to the bundle folder ``out`` with the export command's function.

    Session choice is skipped (the comparison times one thread on purpose) and the
    replay holds at most ``max_frames`` held-out frames. The command's printout
    goes to ``out``'s sibling ``export.log``.
    """
    from slipkit.export.commands import export_main

    cfg = OmegaConf.create(
        {
            "run": str(run),
            "out": str(out),
            "name": out.name,
            "overwrite": True,
            "opset": 17,
            "positive": None,
            "debounce_k": None,
            "regression": {"axis": None, "threshold": 0.0},
            "parity": {"score_eps": None, "atol": 1.0e-4, "max_calls": 5000},
            "replay_max_frames": int(max_frames),
            "choose_session": False,
            "deploy": None,
        }
    )
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), quiet_console():
        path = export_main(cfg)
    (out.parent / f"{out.name}.export.log").write_text(buf.getvalue())
    return Path(path)


def time_bundle(
    bundle_dir: Path, *, max_frames: int, warmup: int, pace: bool = True
) -> DeployCost:
    """p50 and the judged p99 per frame of a bundle's replay through :class:`StreamLoop`.

    One intra-op thread, batch 1, ``warmup`` session calls before the first frame
    (``StreamLoop`` runs them), then the first ``max_frames`` frames one by one, paced
    at their timestamps as ``slipkit-run --check`` paces them (at most
    :func:`~slipkit.runtime.budget.paced_frames`; ``pace=False``: back to back, all
    ``max_frames``); the latency is what the loop records per decision and prepare
    frame (arrival -> end of its work), in us, and the p99 is the latency rule's. A
    paced p99 that is not within the budget is followed by a back-to-back replay of
    the same frames (:attr:`DeployCost.unpaced_latency_us`, module docstring).
    """
    from slipkit.runtime import ReplaySource, SessionSpec, StreamLoop, load_bundle
    from slipkit.runtime.hand import ReplayFeed
    from slipkit.runtime.sources import load_replay

    spec = SessionSpec(
        intra_op_num_threads=1,
        inter_op_num_threads=1,
        graph_optimization_level="all",
        allow_spinning=False,
        warmup=int(warmup),
    )
    bundle = load_bundle(bundle_dir, session=spec)
    m = bundle.manifest
    if bundle.replay_path is None:
        return DeployCost(False, "the bundle holds no replay frames to time")
    frames, times = load_replay(
        bundle.replay_path, tuple(m.frame.shape), m.frame.rate_hz
    )
    n = min(len(frames), int(max_frames))
    if pace:
        n = paced_frames(n, m.frame.rate_hz)
    frames, times = frames[:n], times[:n]
    source = (
        ReplayFeed(frames, times, pace=True, busy_poll=pacing_spins(m.frame.rate_hz))
        if pace
        else ReplaySource(frames, times)
    )
    result = StreamLoop(bundle).run(source)
    lat = frame_latency_us(result)
    p50 = float(np.percentile(lat, 50)) if len(lat) else math.nan
    cost = DeployCost(
        exported=True,
        note="ok",
        latency_us=lat,
        p50_us=p50,
        p99_us=block_p99(lat),
        budget_p99_us=float(m.budget.p99_ms) * 1e3,
        frame_period_us=float(m.budget.frame_period_ms) * 1e3,
        window=int(m.frame.window),
        hop=int(m.frame.hop),
        paced=bool(pace),
    )
    if pace and needs_unpaced(cost.judgement):
        again = StreamLoop(bundle).run(ReplaySource(frames, times))
        cost.unpaced_latency_us = frame_latency_us(again)
    return cost


def needs_unpaced(judged: LatencyJudgement) -> bool:
    """Whether a paced judgement calls for the back-to-back replay: measured and not
    ``within`` (borderline or over)."""
    return judged.status in ("borderline", "over")


def deploy_cost(
    run: Path, folder: Path, *, max_frames: int, warmup: int, keep: bool
) -> DeployCost:
    """Export ``run`` into ``folder`` and time it; an export failure becomes the note.

    Parameters
    ----------
    run : Path
        A run folder (``slipkit train``'s layout).
    folder : Path
        Where the bundle is written (``folder/bundle``).
    max_frames : int
        Replay frames written and timed.
    warmup : int
        Session warm-up calls.
    keep : bool
        Record the bundle's path in the result (the caller keeps the folder).
    """
    from slipkit.errors import SlipkitError

    try:
        bundle = export_run(run, folder / "bundle", max_frames=max_frames)
    except SlipkitError as exc:
        # Unexportable (no exporter for the class, no deployer for the task, parity
        # failed: each an ExportError / SlipkitError): the comparison still reports the
        # estimator, with the reason. Anything else is a bug and propagates.
        return DeployCost(False, f"not exportable: {_first_line(exc)}")
    cost = time_bundle(bundle, max_frames=max_frames, warmup=warmup)
    cost.bundle = bundle if keep else None
    return cost


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    msg = text[0] if text else type(exc).__name__
    return msg if len(msg) <= 160 else msg[:157] + "..."


__all__ = [
    "DeployCost",
    "FitTimer",
    "deploy_cost",
    "export_run",
    "needs_unpaced",
    "quiet_console",
    "time_bundle",
]
