"""A whole hand in one process: several bundles, each on its own input stream.

``slipkit-run --stream NAME=BUNDLE[@SOURCE] --stream ...`` binds each bundle to its
own source; every stream has its own :class:`~slipkit.runtime.loop.StreamLoop` (its
own ring buffer, debounce, bad-frame counts and latency record), and the run reports
p50 / p99 / over-budget counts per stream against that stream's own budget.

Stream syntax (:func:`parse_stream`)
------------------------------------
``NAME=BUNDLE`` replays the bundle's own ``replay.npz``; ``@SOURCE`` picks another
input, one of ``@replay:FILE`` (``.npz`` / ``.npy``), ``@udp:HOST:PORT`` (version-1
frame datagrams, :mod:`slipkit.runtime.sources`) or ``@lsl:STREAM_NAME`` (an LSL inlet,
:mod:`slipkit.runtime.lsl`). NAME is 1-64 letters, digits, ``_``, ``-`` or ``.``,
unique in the run; its position is the stream index in decision datagrams and LSL
samples. The bundle path is everything before the first ``@replay:``, ``@udp:`` or
``@lsl:``. Example::

    slipkit-run --stream index=bundles/biotac_mlp@udp:0.0.0.0:9001 \\
                --stream palm=bundles/fsr@udp:0.0.0.0:9004 --send 127.0.0.1:9100

Scheduling (``mode``)
---------------------
``loop`` (default): one thread serves every stream round-robin, one frame per stream
per pass, each source polled without blocking (UDP sockets are non-blocking and read at
most 64 datagrams per poll, LSL inlets are polled with a zero timeout); when no stream
has a frame the thread waits in ``selectors`` on the UDP sockets until the next paced
replay frame is due (at most :data:`IDLE_WAIT_S`, or :data:`LSL_POLL_S` when an LSL
inlet is open, since an inlet has no file descriptor). A stream of junk datagrams thus
costs the others at most one bounded poll per pass, and a bad frame only flags its own
stream. A slow model still delays the frames of the other streams that arrive during
its call (one thread): with paced replays that wait is in their latency.

``threads``: one thread per stream, each running ``StreamLoop.run`` on a blocking
source. onnxruntime releases the GIL during a call, numpy during larger operations;
the rest of the loop (a few microseconds of Python per frame) takes turns for the GIL.

An error on one stream (onnxruntime failing on a frame, a sink failing) ends that
stream only; it is reported in its summary (``error``) and the run exits 1.

Pacing and latency
------------------
Replays run as fast as the loop takes them unless ``pace`` is set: then each frame is
handed over at ``start + (timestamp - first timestamp)`` on the wall clock, the rate
the sensor produced it. A paced frame's arrival time is its due time when the loop was
busy (behind another stream's work, which is then counted in its latency), and the
time the loop woke up for it when the loop was idle (the operating system's wake-up is
not counted, as it is not for a UDP datagram, whose arrival is stamped when it is read).
For UDP in ``loop`` mode a datagram is stamped when it is read, so time spent queued
in the socket while another stream computes is not counted; paced replays measure it.
In ``threads`` mode a wake-up is stamped after the thread holds the GIL again, so a
wait for the GIL after a sleep or a receive is not counted either.

Busy polling (``--busy-poll``, ``--spin-us``)
--------------------------------------------
A decision right after a sleep costs several times one made back to back (caches and
TLB gone cold, the core in an idle state, the vCPU descheduled). ``busy_poll`` never
sleeps: in ``loop`` mode the thread polls every stream again at once when none had a
frame (no ``select``), so paced replay frames are taken by spinning on
:func:`time.perf_counter_ns` to their due time and UDP / LSL inputs are read without
blocking; in ``threads`` mode (single-bundle runs) the sources spin the same way. It
keeps one core 100 % busy: pair it with ``--cpus``. ``--timeout``, ``--wait``, the end
of a replay and Ctrl-C end it as they end a sleeping run (every pass checks them).
Under SCHED_FIFO the kernel's RT throttling (``sched_rt_runtime_us``, 0.95 s of every
1 s by default) stops a thread that never sleeps for the rest of each period, so
``--realtime`` does not include it. ``spin_us`` is the middle way: sleep until
``spin_us`` before the next paced frame is due, then spin (the thread still sleeps
between frames, so SCHED_FIFO is not throttled). A frame taken by spinning arrives at
its due time, so its latency includes how late the spin noticed it.

Standard library, numpy and onnxruntime only (``pylsl`` lazily, for LSL streams).
"""

from __future__ import annotations

import argparse
import re
import selectors
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slipkit.errors import SlipkitError
from slipkit.runtime.budget import UNPACED_NOTE
from slipkit.runtime.bundle import DEFAULT_DEADLINE_S, Bundle, load_bundle
from slipkit.runtime.errors import FrameError, OptionError
from slipkit.runtime.loop import LoopResult, StreamLoop
from slipkit.runtime.realtime import RealtimeOptions, pinned_session
from slipkit.runtime.session import ORT_ERRORS
from slipkit.runtime.sinks import (
    MAX_STREAMS,
    Fanout,
    JsonlSink,
    UdpSink,
    parse_address,
)
from slipkit.runtime.sources import (
    DEFAULT_WAIT_S,
    RESYNC_AFTER,
    Frame,
    UdpSource,
    load_replay,
)

#: Source kinds of ``NAME=BUNDLE@KIND:TARGET``.
SOURCE_KINDS = ("replay", "udp", "lsl")
#: Scheduling modes.
MODES = ("loop", "threads")
#: Longest idle wait of the one-thread loop, s (deadlines are checked after it).
IDLE_WAIT_S = 0.05
#: Idle wait of the one-thread loop while an LSL inlet is open, s (inlets have no fd).
LSL_POLL_S = 0.0005
#: Longest ``spin_us`` (``--spin-us``), us: 0.1 s of spinning before each frame.
MAX_SPIN_US = 100_000.0
_NAME = re.compile(r"[A-Za-z0-9_.-]{1,64}")
_SOURCE = re.compile(r"@(replay|udp|lsl):")
#: What looks like a source marker of any kind (``@bogus:``).
_ANY_SOURCE = re.compile(r"@([A-Za-z][A-Za-z0-9_-]*):")


@dataclass(frozen=True)
class StreamBinding:
    """One ``--stream`` value: a named bundle bound to its input.

    Attributes
    ----------
    name : str
        The stream's name (unique in a run).
    bundle : Path
        The bundle folder.
    kind : str
        ``replay``, ``udp`` or ``lsl`` (:data:`SOURCE_KINDS`).
    target : str or None
        The replay file, ``HOST:PORT`` or LSL stream name; None: the bundle's replay.
    """

    name: str
    bundle: Path
    kind: str = "replay"
    target: str | None = None

    def describe(self) -> str:
        """``NAME=BUNDLE@KIND:TARGET`` as it would be written on the command line."""
        src = "" if self.target is None else f"@{self.kind}:{self.target}"
        return f"{self.name}={self.bundle}{src}"


def parse_stream(text: str, option: str = "--stream") -> StreamBinding:
    """Parse ``NAME=BUNDLE[@replay:FILE|@udp:HOST:PORT|@lsl:STREAM]`` (module docstring).

    Raises
    ------
    OptionError
        Naming ``option`` and the part that is wrong.
    """
    name, sep, rest = text.partition("=")
    if not sep or not rest:
        raise OptionError(
            option,
            f"must be NAME=BUNDLE[@replay:FILE|@udp:HOST:PORT|@lsl:STREAM]; got {text!r}",
        )
    if not _NAME.fullmatch(name):
        raise OptionError(
            option,
            f"stream name {name!r} must be 1-64 letters, digits, '_', '-' or '.'",
        )
    m = _SOURCE.search(rest)
    other = _ANY_SOURCE.search(rest) if m is None else None
    if other is not None and not Path(rest).is_dir():
        raise OptionError(
            option,
            f"{name}: unknown source kind {other.group(1)!r} in "
            f"'@{other.group(1)}:'; one of @replay:FILE, @udp:HOST:PORT, "
            f"@lsl:STREAM; got {text!r}",
        )
    if m is None:
        bundle, kind, target = rest, "replay", None
    else:
        bundle, kind, target = rest[: m.start()], m.group(1), rest[m.end() :]
        if not target:
            raise OptionError(
                option, f"{name}: '@{kind}:' needs a target; got {text!r}"
            )
    if not bundle:
        raise OptionError(option, f"{name}: no bundle folder before '@'; got {text!r}")
    if kind == "udp":
        assert target is not None
        parse_address(target, f"{option} {name}")
    return StreamBinding(name, Path(bundle), kind, target)


def check_bindings(bindings: Sequence[StreamBinding], option: str = "--stream") -> None:
    """Names unique, at most :data:`MAX_STREAMS` streams, no UDP port bound twice."""
    if len(bindings) > MAX_STREAMS:
        raise OptionError(option, f"at most {MAX_STREAMS} streams; got {len(bindings)}")
    seen: set[str] = set()
    ports: dict[str, str] = {}
    for b in bindings:
        if b.name in seen:
            raise OptionError(option, f"stream name {b.name!r} is given twice")
        seen.add(b.name)
        if b.kind == "udp" and b.target is not None:
            port = b.target.rpartition(":")[2]
            if port != "0" and b.target in ports:
                raise OptionError(
                    option,
                    f"streams {ports[b.target]!r} and {b.name!r} both listen on {b.target}",
                )
            ports[b.target] = b.name


def check_spin_us(spin_us: float, option: str = "--spin-us") -> float:
    """``spin_us`` checked to be in [0, :data:`MAX_SPIN_US`] us; OptionError naming ``option``."""
    if not (
        isinstance(spin_us, int | float)
        and not isinstance(spin_us, bool)
        and 0 <= spin_us <= MAX_SPIN_US  # False for NaN too
    ):
        raise OptionError(
            option, f"must be in [0, {MAX_SPIN_US:g}] us; got {spin_us!r}"
        )
    return float(spin_us)


class ReplayFeed:
    """Recorded frames, handed over as fast as taken or paced at their own times.

    Parameters
    ----------
    frames : ndarray of shape (n, *frame.shape)
        The frames.
    timestamps : ndarray of shape (n,)
        Their times, s (non-decreasing).
    pace : bool
        Hand frame ``i`` over at ``start + timestamps[i] - timestamps[0]`` (wall
        clock) instead of at once (module docstring, *Pacing and latency*).
    max_frames : int, optional
        Only the first ``max_frames`` frames.
    busy_poll : bool
        Blocking iteration spins on :func:`time.perf_counter_ns` up to each paced
        frame's due time instead of sleeping (module docstring, *Busy polling*).
    spin_ns : int
        Without ``busy_poll``: sleep until ``spin_ns`` before each due time and spin
        the rest (0: sleep the whole wait), ns.

    Attributes
    ----------
    ended : bool
        Every frame was handed over.
    """

    def __init__(
        self,
        frames: NDArray[np.floating],
        timestamps: NDArray[np.float64],
        *,
        pace: bool = False,
        max_frames: int | None = None,
        busy_poll: bool = False,
        spin_ns: int = 0,
    ) -> None:
        n = len(frames) if max_frames is None else min(len(frames), max_frames)
        self.busy_poll = bool(busy_poll)
        self.spin_ns = int(spin_ns)
        self.frames = frames[:n]
        self.timestamps = timestamps[:n]
        self.pace = bool(pace)
        rel = np.asarray(self.timestamps, dtype=np.float64) - (
            float(self.timestamps[0]) if n else 0.0
        )
        self._offset_ns = (rel * 1e9).astype(np.int64).tolist()
        self._ts = self.timestamps.tolist()
        self._i = 0
        self._start_ns = 0
        self.ended = n == 0

    def __len__(self) -> int:
        return len(self.frames)

    def start(self, start_ns: int | None = None) -> None:
        """Set the wall-clock start (``time.perf_counter_ns``) the pacing counts from."""
        self._start_ns = time.perf_counter_ns() if start_ns is None else start_ns
        self._i = 0
        self.ended = len(self.frames) == 0

    def next_due_ns(self) -> int | None:
        """When the next frame is due (``perf_counter_ns``); None when ended or unpaced."""
        if self.ended or not self.pace:
            return None
        return self._start_ns + self._offset_ns[self._i]

    def poll(self, woke_ns: int) -> Frame | None:
        """The next frame if it is due, else None; never blocks.

        ``woke_ns`` is when the polling loop last woke from a wait: a paced frame that
        came due during that wait arrives then, one that came due while the loop was
        busy arrives at its due time.
        """
        i = self._i
        if self.ended:
            return None
        now = time.perf_counter_ns()
        if self.pace:
            due = self._start_ns + self._offset_ns[i]
            if now < due:
                return None
            arrival = max(due, woke_ns)
        else:
            arrival = now
        self._i = i + 1
        self.ended = self._i == len(self.frames)
        return Frame(i, self._ts[i], self.frames[i], arrival)

    def __iter__(self) -> Iterator[Frame]:
        """Blocking iteration (one thread per stream): sleeps until each paced frame is due."""
        if not self._start_ns:
            self.start()
        clock, sleep = time.perf_counter_ns, time.sleep
        frames, ts, start = self.frames, self._ts, self._start_ns
        # Sleep until this long before a due time, then spin (busy polling: never sleep).
        early = -1 if self.busy_poll else self.spin_ns
        for i in range(self._i, len(frames)):
            if self.pace:
                due = start + self._offset_ns[i]
                now = clock()
                arrival = due
                if now < due:
                    if early >= 0 and due - now > early:
                        sleep((due - now - early) / 1e9)
                        now = clock()
                    if now >= due:
                        arrival = now  # woke up late: the wake-up is not counted
                    else:
                        # Spin to the due time (the core stays hot); a frame handed
                        # over by spinning arrives at its due time.
                        while clock() < due:
                            pass
            else:
                arrival = clock()
            self._i = i + 1
            yield Frame(i, ts[i], frames[i], arrival)
        self.ended = True


@dataclass
class HandStream:
    """One stream of a hand: its binding, bundle, loop, source and sinks.

    Attributes
    ----------
    index : int
        Position in the run (the stream index of datagrams and LSL samples).
    binding : StreamBinding
        What the command line said.
    bundle : Bundle
        The loaded bundle.
    loop : StreamLoop
        Its own loop.
    source : ReplayFeed, UdpSource or LslSource
        Its own input.
    udp_sink : UdpSink or None
        Its decision datagram sink (``--send``).
    result : LoopResult or None
        The decisions, once the stream ended.
    error : str or None
        Why the stream stopped early (onnxruntime failed on a frame, a sink failed).
    """

    index: int
    binding: StreamBinding
    bundle: Bundle
    loop: StreamLoop
    source: Any
    udp_sink: UdpSink | None = None
    lsl_hook: Any = None
    result: LoopResult | None = None
    error: str | None = None
    _bug: BaseException | None = field(default=None, repr=False)

    @property
    def name(self) -> str:
        """The stream's name."""
        return self.binding.name

    def finish(self) -> None:
        """Take the loop's result (also after an error: the decisions made so far)."""
        self.result = self.loop.result()

    def fail(self, exc: BaseException) -> None:
        """End this stream with a one-line reason."""
        self.error = " ".join(str(exc).split()) or type(exc).__name__


def open_source(
    binding: StreamBinding,
    bundle: Bundle,
    *,
    pace: bool = False,
    max_frames: int | None = None,
    timeout_s: float = 2.0,
    wait_s: float = DEFAULT_WAIT_S,
    resync_after: int = RESYNC_AFTER,
    pylsl: Any = None,
    busy_poll: bool = False,
    spin_us: float = 0.0,
) -> Any:
    """The source a binding names, opened (UDP bound; LSL resolved later, on start).

    ``busy_poll`` and ``spin_us`` apply to blocking iteration (``threads`` mode);
    ``loop`` mode polls every source itself (:func:`run_streams`).

    Raises
    ------
    SlipkitError
        A bad replay file, an address that cannot be bound, a missing pylsl.
    """
    f = bundle.manifest.frame
    if binding.kind == "replay":
        path = (
            Path(binding.target) if binding.target is not None else bundle.replay_path
        )
        if path is None:
            raise FrameError(
                str(bundle.path),
                "no frames: the bundle has no replay.npz; give @SOURCE",
            )
        frames, times = load_replay(path, f.shape, f.rate_hz)
        return ReplayFeed(
            frames,
            times,
            pace=pace,
            max_frames=max_frames,
            busy_poll=busy_poll,
            spin_ns=int(spin_us * 1000),
        )
    if binding.kind == "udp":
        assert binding.target is not None
        host, port = parse_address(binding.target, "--stream")
        return UdpSource(
            host,
            port,
            f.shape,
            max_frames=max_frames,
            timeout_s=timeout_s,
            wait_s=wait_s,
            resync_after=resync_after,
            busy_poll=busy_poll,
        )
    from slipkit.runtime.lsl import LslSource

    assert binding.target is not None
    return LslSource(
        binding.target,
        f.shape,
        max_frames=max_frames,
        timeout_s=timeout_s,
        wait_s=wait_s,
        pylsl=pylsl,
        busy_poll=busy_poll,
    )


def _close(stream: HandStream) -> None:
    close = getattr(stream.source, "close", None)
    if close is not None:
        close()
    if stream.udp_sink is not None:
        stream.udp_sink.close()


#: What ends one stream (not the run): onnxruntime on a frame, a slipkit error, a
#: failed write or send.
_STREAM_ERRORS: tuple[type[BaseException], ...] = (*ORT_ERRORS, SlipkitError, OSError)


def _run_loop(
    streams: list[HandStream],
    start_ns: int,
    *,
    busy_poll: bool = False,
    spin_ns: int = 0,
) -> None:
    """Serve every stream from this thread, round-robin (module docstring, ``loop``).

    ``busy_poll``: never wait, poll every stream again at once; ``spin_ns``: wait
    until that long before the next paced frame is due, then poll without waiting
    (module docstring, *Busy polling*).
    """
    sel = selectors.DefaultSelector()
    polls_lsl = False
    for s in streams:
        src = s.source
        if not isinstance(src, ReplayFeed):
            try:
                src.start_polling()
            except _STREAM_ERRORS as exc:
                s.fail(exc)
                continue
            if isinstance(src, UdpSource):
                sel.register(src.sock, selectors.EVENT_READ)
            else:
                polls_lsl = True
    # Paced replays start after the live sources are open (an LSL inlet resolves first).
    start_ns = max(start_ns, time.perf_counter_ns())
    for s in streams:
        if isinstance(s.source, ReplayFeed):
            s.source.start(start_ns)
    active = [s for s in streams if s.error is None]
    clock = time.perf_counter_ns
    woke = clock()
    try:
        while active:
            got = False
            for s in tuple(active):
                src = s.source
                frame = src.poll(woke) if isinstance(src, ReplayFeed) else src.poll()
                if frame is None:
                    if src.ended:
                        active.remove(s)
                    continue
                got = True
                try:
                    s.loop.step(frame.values, frame.timestamp, frame.arrival_ns)
                except _STREAM_ERRORS as exc:
                    s.fail(exc)
                    active.remove(s)
            if got or not active:
                continue
            if busy_poll:
                woke = clock()
                continue
            wait = LSL_POLL_S if polls_lsl else IDLE_WAIT_S
            now = clock()
            for s in active:
                src = s.source
                if isinstance(src, ReplayFeed):
                    due = src.next_due_ns()
                    if due is not None:
                        wait = min(wait, max(due - now - spin_ns, 0) / 1e9)
            if wait > 0:
                if sel.get_map():
                    sel.select(wait)
                else:
                    time.sleep(wait)
            woke = clock()
    finally:
        sel.close()


def _thread_body(s: HandStream, start_ns: int) -> None:
    src = s.source
    try:
        if isinstance(src, ReplayFeed):
            src.start(start_ns)
        s.loop.run(src)
    except SlipkitError as exc:  # run() names onnxruntime's errors as BundleError
        s.fail(exc)
    except OSError as exc:
        s.fail(exc)
    except BaseException as exc:  # a bug: re-raised in the main thread
        s.fail(exc)
        s._bug = exc


def _run_threads(streams: list[HandStream], start_ns: int) -> None:
    """One thread per stream (module docstring, ``threads``)."""
    threads = [
        threading.Thread(
            target=_thread_body,
            args=(s, start_ns),
            name=f"slipkit-{s.name}",
            daemon=True,
        )
        for s in streams
    ]
    for t in threads:
        t.start()
    for t in threads:
        while t.is_alive():
            t.join(0.5)
    for s in streams:
        if s._bug is not None:
            raise s._bug


def run_streams(
    streams: list[HandStream],
    mode: str = "loop",
    *,
    start_delay_s: float = 0.01,
    busy_poll: bool = False,
    spin_us: float = 0.0,
) -> None:
    """Run every stream to its end in ``mode`` (:data:`MODES`); results land on the streams.

    Paced replays count from one common start, ``start_delay_s`` after the call (so
    every thread has started before the first frame is due). ``busy_poll`` and
    ``spin_us`` (us) are for ``loop`` mode (module docstring, *Busy polling*; in
    ``threads`` mode the sources carry their own ``busy_poll`` and ``spin_ns``).
    """
    if mode not in MODES:
        raise OptionError("mode", f"must be one of {', '.join(MODES)}; got {mode!r}")
    check_spin_us(spin_us)
    start_ns = time.perf_counter_ns() + int(start_delay_s * 1e9)
    try:
        if mode == "loop":
            _run_loop(
                streams,
                start_ns,
                busy_poll=busy_poll,
                spin_ns=int(spin_us * 1000),
            )
        else:
            _run_threads(streams, start_ns)
    finally:
        for s in streams:
            s.finish()
            _close(s)


def stream_summary(s: HandStream) -> dict[str, Any]:
    """One stream's JSON summary: the loop's, plus its name, source and sinks."""
    assert s.result is not None
    out: dict[str, Any] = {
        "stream": s.name,
        "index": s.index,
        "bundle_path": str(s.binding.bundle),
        **s.result.summary(),
        "source": s.binding.describe().split("=", 1)[1],
        "error": s.error,
    }
    src = s.source
    if isinstance(src, UdpSource):
        out["udp"] = {
            "address": src.where,
            "received": src.n_received,
            "rejected": src.n_rejected,
            "lost": src.n_lost,
            "resyncs": src.n_resyncs,
            "last_error": src.last_error,
            "ended": "wait"
            if src.waited_out
            else "timeout"
            if src.timed_out
            else "frames",
        }
    elif not isinstance(src, ReplayFeed):
        out["lsl"] = {
            "stream": src.name,
            "received": src.n_received,
            "last_error": src.last_error,
            "ended": "wait"
            if src.waited_out
            else "timeout"
            if src.timed_out
            else "frames",
        }
    if s.udp_sink is not None:
        out["send"] = {
            "sent": s.udp_sink.n_sent,
            "errors": s.udp_sink.n_errors,
            "last_error": s.udp_sink.last_error,
        }
    if s.lsl_hook is not None:
        out["lsl_out_pushed"] = s.lsl_hook.n_pushed
    return out


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.4f}"


def table_lines(summaries: list[dict[str, Any]]) -> list[str]:
    """The per-stream table ``slipkit-run --stream`` prints (p99: the latency rule's,
    :mod:`slipkit.runtime.budget`, judged against the budget in the verdict column)."""
    head = (
        f"{'stream':<12} {'bundle':<16} {'frames':>7} {'decisions':>9} {'bad':>5} "
        f"{'skipped':>7} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8} {'budget ms':>9} "
        f"{'over':>5}  verdict"
    )
    lines = [head]
    for s in summaries:
        lat = s["latency_ms"] or {}
        judged = (s.get("latency_check") or {}).get("p99_ms")
        # the latency rule's status (slipkit.runtime.budget): within, borderline, over
        verdict = (
            "no decisions"
            if s["within_budget"] is None
            else s["latency_check"]["status"]
        )
        if s["error"]:
            verdict += " (stream failed)"
        lines.append(
            f"{s['stream'][:12]:<12} {s['bundle'][:16]:<16} {s['frames']:>7} "
            f"{s['decisions']:>9} {s['bad_frames']:>5} {s['skipped_windows']:>7} "
            f"{_ms(lat.get('p50')):>8} {_ms(judged):>8} {_ms(lat.get('max')):>8} "
            f"{s['budget_ms']['p99']:>9.4f} {s['over_budget']:>5}  {verdict}"
        )
    return lines


def build_streams(
    args: argparse.Namespace,
    bindings: Sequence[StreamBinding],
    rt_opts: RealtimeOptions | None = None,
) -> list[HandStream]:
    """Load every bundle, open every source, attach the sinks ``args`` asks for.

    With ``rt_opts.pin_threads`` every bundle's session gets one intra-op and one
    inter-op thread (:func:`~slipkit.runtime.realtime.pinned_session`).

    Any failure closes what was opened and raises an :class:`OptionError` naming
    ``--stream`` and the stream.
    """
    lock = threading.Lock()
    outlet = None
    if args.lsl_out is not None:
        from slipkit.runtime.lsl import LslOutlet

        outlet = LslOutlet(args.lsl_out, [b.name for b in bindings])
    streams: list[HandStream] = []
    try:
        for i, b in enumerate(bindings):
            try:
                bundle = load_bundle(
                    b.bundle,
                    deadline_s=getattr(args, "load_deadline", DEFAULT_DEADLINE_S),
                    key=getattr(args, "key_bytes", None),  # slipkit-run --key
                )
                if rt_opts is not None and rt_opts.pin_threads:
                    bundle = bundle.with_session(
                        pinned_session(bundle.session_spec, rt_opts)
                    )
                source = open_source(
                    b,
                    bundle,
                    pace=args.pace,
                    max_frames=args.frames,
                    timeout_s=args.timeout,
                    wait_s=args.wait,
                    resync_after=args.resync_after,
                    busy_poll=getattr(args, "busy_poll", False),
                    spin_us=getattr(args, "spin_us", 0.0),
                )
                sinks: list[Any] = []
                udp_sink = None
                if args.send is not None:
                    host, port = parse_address(args.send, "--send")
                    udp_sink = UdpSink(host, port, stream=i)
                    sinks.append(udp_sink)
                if args.jsonl:
                    sinks.append(JsonlSink(label=b.name, lock=lock))
                hook_lsl = None
                if outlet is not None:
                    hook_lsl = outlet.hook(i)
                    sinks.append(hook_lsl)
                hook = (
                    None
                    if not sinks
                    else sinks[0]
                    if len(sinks) == 1
                    else Fanout(*sinks)
                )
                loop = StreamLoop(bundle, io_binding=args.io_binding, on_decision=hook)
            except SlipkitError as exc:
                raise OptionError(
                    "--stream", f"{b.name}: {' '.join(str(exc).split())}"
                ) from None
            streams.append(
                HandStream(
                    i, b, bundle, loop, source, udp_sink=udp_sink, lsl_hook=hook_lsl
                )
            )
    except BaseException:
        for s in streams:
            _close(s)
        raise
    return streams


def run_hand_cli(
    args: argparse.Namespace, rt_opts: RealtimeOptions | None = None
) -> tuple[dict[str, Any], int]:
    """``slipkit-run --stream ...``: build, run, print the table; (summary, exit status).

    ``rt_opts``: the real-time options (only ``pin_threads`` is applied here, to each
    bundle's session; the CLI applies the rest to the process).
    """
    bindings = [parse_stream(t) for t in args.stream]
    check_bindings(bindings)
    streams = build_streams(args, bindings, rt_opts)
    for s in streams:
        src = s.source
        if isinstance(src, UdpSource):
            print(
                f"{s.name}: listening on {src.where} (frames of {src.n_values} float32 values, format v1)",
                file=sys.stderr,
                flush=True,
            )
    run_streams(
        streams,
        args.hand_mode,
        busy_poll=getattr(args, "busy_poll", False),
        spin_us=getattr(args, "spin_us", 0.0),
    )
    summaries = [stream_summary(s) for s in streams]
    print(
        f"hand: {len(streams)} streams, mode {args.hand_mode}"
        + (
            ", replays paced at their timestamps"
            if args.pace
            else f", replays {UNPACED_NOTE}"
            if any(b.kind == "replay" for b in bindings)
            else ""
        )
        + (", busy polling" if getattr(args, "busy_poll", False) else "")
        + (
            f", spinning {args.spin_us:g} us before each due frame"
            if getattr(args, "spin_us", 0.0)
            else ""
        )
    )
    for line in table_lines(summaries):
        print(line)
    status = 0
    for row in summaries:
        for key in ("udp", "lsl"):
            live = row.get(key)
            if live is None:
                continue
            extra = (
                f", {live['rejected']} rejected, {live['lost']} lost, {live['resyncs']} resyncs"
                if key == "udp"
                else ""
            )
            print(
                f"{row['stream']}: {key} {live['received']} received{extra}"
                + (f" (last error: {live['last_error']})" if live["last_error"] else "")
            )
            if live["ended"] == "wait":
                print(
                    f"{row['stream']}: no frame arrived within --wait {args.wait:g} s"
                )
                status = 1
        if row["error"]:
            print(f"{row['stream']}: stream failed: {row['error']}")
            status = 1
        if "send" in row:
            print(
                f"{row['stream']}: send {row['send']['sent']} decisions to {args.send}, "
                f"{row['send']['errors']} send errors"
            )
    if args.lsl_out is not None:
        pushed = sum(r.get("lsl_out_pushed", 0) for r in summaries)
        print(f"lsl-out: {pushed} decisions pushed to LSL stream {args.lsl_out!r}")
    # A stream without decisions has not met its budget (as --check in single mode).
    all_met = all(r["within_budget"] is True for r in summaries)
    if args.check:
        if not all_met:
            status = 1
        print(f"check: {'passed' if status == 0 else 'FAILED'}")
    out = {
        "hand": {
            "mode": args.hand_mode,
            "pace": bool(args.pace),
            "busy_poll": bool(getattr(args, "busy_poll", False)),
            "spin_us": float(getattr(args, "spin_us", 0.0)),
            "streams": [s.name for s in streams],
            "within_budget": all_met,
        },
        "streams": summaries,
        "io_binding": bool(args.io_binding),
    }
    return out, status
