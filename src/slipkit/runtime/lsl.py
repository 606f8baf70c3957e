"""Lab Streaming Layer (LSL): sensor frames in through an inlet, decisions out through an outlet.

LSL is what prosthetics and neuroscience labs use to time-align streams across
programs and machines (https://labstreaminglayer.readthedocs.io). slipkit reaches it
through ``pylsl`` (the official Python binding, which ships ``liblsl``), an optional
extra: ``pip install 'slipkit[lsl]'``. ``pylsl`` is imported only when an LSL source or
sink is made, so the runtime keeps its numpy + onnxruntime promise otherwise; without
it, :class:`~slipkit.runtime.errors.OptionError` says in one line how to install it.

Inlet (:class:`LslSource`)
    Resolves a stream by its LSL *name* (``--lsl NAME``), checks that it carries one
    numeric sample of ``prod(frame.shape)`` channels per frame, and yields each sample
    as a :class:`~slipkit.runtime.sources.Frame`: ``timestamp`` is the sample's LSL
    time stamp mapped to this machine's LSL clock (``proc_clocksync``), the frame
    index counts samples from 0. ``wait_s`` bounds the resolution and the first
    sample, ``timeout_s`` the silence after any sample, as for UDP.

Outlet (:class:`LslOutlet`)
    One irregular-rate stream (``--lsl-out NAME``, content type ``SlipDecisions``) of
    8 ``double`` channels per decision, in the order of :data:`DECISION_CHANNELS`:
    stream index, frame index, frame timestamp (s; NaN when none), score, class
    index (-1: none), slip (0/1), declared (0/1), latency (ns). The sample's LSL
    time stamp is the LSL clock when the decision is pushed, so a recorder
    (LabRecorder) aligns decisions with every other LSL stream; for an LSL inlet
    the frame timestamp channel is on the same clock. The channel labels and the
    stream names (``desc/streams/stream``) are in the stream's XML description.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Iterator
from types import ModuleType, TracebackType
from typing import Any

import numpy as np

from slipkit.runtime.errors import FrameError, OptionError
from slipkit.runtime.sources import DEFAULT_WAIT_S, MAX_TIMEOUT_S, Frame

#: What ``slipkit[lsl]`` installs.
PYLSL_REQUIREMENT = "pylsl>=1.16"
#: Channels of a decision sample, in order.
DECISION_CHANNELS = (
    "stream",
    "frame",
    "timestamp",
    "score",
    "class",
    "slip",
    "declared",
    "latency_ns",
)
#: LSL content type of the decision outlet.
DECISION_TYPE = "SlipDecisions"
#: How long one resolve attempt waits, s, when ``wait_s`` is 0 (forever).
_RESOLVE_STEP_S = 1.0


def import_pylsl(option: str = "--lsl") -> ModuleType:
    """``pylsl``, or an :class:`OptionError` naming ``option`` and how to install it.

    pylsl raises ``RuntimeError`` (or ``OSError``) when it is installed but its bundled
    ``liblsl`` does not load (a platform without a wheel): that is named too.
    """
    try:
        import pylsl
    except ImportError:
        raise OptionError(
            option,
            f"needs pylsl, which is not installed: pip install 'slipkit[lsl]' "
            f"({PYLSL_REQUIREMENT})",
        ) from None
    except (RuntimeError, OSError) as exc:
        raise OptionError(
            option,
            "pylsl is installed but its liblsl did not load: "
            + " ".join(str(exc).split()),
        ) from None
    return pylsl


def _check_seconds(name: str, value: Any, *, zero_ok: bool) -> float:
    ok = (
        isinstance(value, int | float)
        and not isinstance(value, bool)
        and (0 <= value if zero_ok else 0 < value)
        and value <= MAX_TIMEOUT_S  # False for NaN too
    )
    if not ok:
        lo = "[0" if zero_ok else "(0"
        raise OptionError(name, f"must be in {lo}, {MAX_TIMEOUT_S:g}] s; got {value!r}")
    return float(value)


class LslSource:
    """Frames from an LSL stream, found by name.

    Parameters
    ----------
    name : str
        The LSL stream's ``name`` property.
    frame_shape : tuple of int
        The bundle's ``frame.shape``: the stream must have ``prod(frame_shape)``
        channels of a numeric format.
    max_frames : int, optional
        Stop after this many samples.
    timeout_s : float
        After the first sample, stop when none came for this long, s; in (0, 86400].
    wait_s : float
        Stop when the stream was not found, or sent no sample, this long after the
        iteration started, s; 0 waits forever; in [0, 86400].
    pylsl : module, optional
        The ``pylsl`` module (tests pass a stand-in); imported when omitted.
    busy_poll : bool
        Iteration pulls with a zero timeout over and over instead of waiting in
        ``pull_sample``: the thread never sleeps (one core kept busy; ``slipkit-run
        --busy-poll``, as :class:`~slipkit.runtime.sources.UdpSource`).

    Attributes
    ----------
    where : str
        ``lsl NAME`` (for messages and summaries).
    n_received : int
        Samples handed to the loop.
    timed_out, waited_out : bool
        Why the stream ended (as :class:`~slipkit.runtime.sources.UdpSource`).
    ended : bool
        :meth:`poll` has nothing more to give.
    last_error : str or None
        The inlet's error when the stream was lost.
    """

    def __init__(
        self,
        name: str,
        frame_shape: tuple[int, ...],
        *,
        max_frames: int | None = None,
        timeout_s: float = 2.0,
        wait_s: float = DEFAULT_WAIT_S,
        pylsl: ModuleType | None = None,
        busy_poll: bool = False,
    ) -> None:
        if not isinstance(name, str) or not name.strip() or "\0" in name:
            raise OptionError("--lsl", f"must be an LSL stream name; got {name!r}")
        self.timeout_s = _check_seconds("timeout_s", timeout_s, zero_ok=False)
        self.wait_s = _check_seconds("wait_s", wait_s, zero_ok=True)
        if max_frames is not None and not (
            isinstance(max_frames, int) and max_frames >= 1
        ):
            raise OptionError("max_frames", f"must be >= 1; got {max_frames!r}")
        self._lsl = pylsl if pylsl is not None else import_pylsl("--lsl")
        self.name = name
        self.where = f"lsl {name}"
        self.frame_shape = tuple(frame_shape)
        self.n_values = math.prod(self.frame_shape)
        self.max_frames = max_frames
        self.busy_poll = bool(busy_poll)
        # The received sample is copied into this buffer (the loop copies it again
        # into its ring buffer at once, as for UDP).
        self._values = np.zeros(self.frame_shape, dtype=np.float64)
        self._flat = self._values.reshape(-1)
        self._inlet: Any = None
        self.n_received = 0
        self.timed_out = self.waited_out = self.ended = False
        self.last_error: str | None = None
        self._deadline: float | None = None

    # -- resolution -------------------------------------------------------------
    def open(self) -> None:
        """Resolve the stream (within ``wait_s``), check its channels, open an inlet.

        Ends the source (``waited_out``) when the stream is not found in time.

        Raises
        ------
        FrameError
            The stream's channel count or format does not fit the bundle's frame.
        """
        if self._inlet is not None or self.ended:
            return
        lsl, now = self._lsl, time.monotonic
        start = now()
        self._deadline = None if self.wait_s == 0 else start + self.wait_s
        found: list[Any] = []
        while not found:
            step = (
                _RESOLVE_STEP_S
                if self._deadline is None
                else max(self._deadline - now(), 0.0)
            )
            found = list(lsl.resolve_byprop("name", self.name, 1, step))
            if not found and self._deadline is not None and now() >= self._deadline:
                self.waited_out = self.ended = True
                return
        info = found[0]
        n = int(info.channel_count())
        if n != self.n_values:
            raise FrameError(
                self.where,
                f"the stream has {n} channels; the bundle's frame has {self.n_values} "
                f"values (frame.shape {list(self.frame_shape)})",
            )
        if int(info.channel_format()) == int(lsl.cf_string):
            raise FrameError(
                self.where, "the stream's channel format is string; frames are numbers"
            )
        flags = int(lsl.proc_clocksync)
        # pylsl's default buffer (360 s of samples): a shorter one would drop the
        # oldest frames silently when the loop falls behind; max_chunklen=1 asks the
        # outlet to send each sample as it is pushed.
        self._inlet = lsl.StreamInlet(info, max_chunklen=1, processing_flags=flags)
        left = 32e6 if self._deadline is None else max(self._deadline - now(), 0.1)
        try:
            self._inlet.open_stream(timeout=left)
        # pylsl raises TimeoutError, or its LostError (a RuntimeError) for a stream
        # that went away between resolution and subscription.
        except (TimeoutError, RuntimeError, OSError) as exc:
            self.close()
            raise FrameError(
                self.where, f"could not subscribe to the stream: {exc}"
            ) from None

    def close(self) -> None:
        """Close the inlet (if it was opened)."""
        if self._inlet is not None:
            # Closing a lost stream must not fail a run.
            with contextlib.suppress(Exception):
                self._inlet.close_stream()
            self._inlet = None

    def __enter__(self) -> LslSource:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- reading ------------------------------------------------------------------
    def _pull(self, timeout: float) -> Frame | None:
        try:
            sample, ts = self._inlet.pull_sample(timeout=timeout)
        # pylsl's LostError (its class differs across pylsl versions) and its kin.
        except Exception as exc:
            self.last_error = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            self.timed_out = self.ended = True
            return None
        if sample is None:
            return None
        arrival = time.perf_counter_ns()
        self._flat[:] = sample
        index = self.n_received
        self.n_received += 1
        self._deadline = time.monotonic() + self.timeout_s
        return Frame(index, float(ts), self._values, arrival)

    def _expire(self) -> None:
        if self.n_received:
            self.timed_out = True
        else:
            self.waited_out = True
        self.ended = True

    def _full(self) -> bool:
        return self.max_frames is not None and self.n_received >= self.max_frames

    def __iter__(self) -> Iterator[Frame]:
        self.open()
        if self.busy_poll:
            poll = self.poll
            while not self.ended:
                frame = poll()
                if frame is not None:
                    yield frame
            return
        now = time.monotonic
        while not self.ended and not self._full():
            left = 3600.0 if self._deadline is None else self._deadline - now()
            if left <= 0:
                self._expire()
                return
            frame = self._pull(min(left, 3600.0))
            if frame is not None:
                yield frame

    def start_polling(self) -> None:
        """Resolve and open the inlet now, for :meth:`poll`."""
        self.open()

    def poll(self) -> Frame | None:
        """The next sample if one is buffered, else None; never blocks."""
        if self.ended:
            return None
        if self._full():
            self.ended = True
            return None
        frame = self._pull(0.0)
        if (
            frame is None
            and not self.ended
            and self._deadline is not None
            and time.monotonic() > self._deadline
        ):
            self._expire()
        return frame


class LslOutlet:
    """A decision outlet: one LSL sample of :data:`DECISION_CHANNELS` per decision.

    Parameters
    ----------
    name : str
        The LSL stream name (``--lsl-out``).
    streams : sequence of str
        The runtime's stream names, in index order (one for a single bundle);
        written into the stream description.
    pylsl : module, optional
        The ``pylsl`` module (tests pass a stand-in); imported when omitted.

    Attributes
    ----------
    n_pushed : int
        Decisions pushed (all streams).
    """

    def __init__(
        self,
        name: str,
        streams: tuple[str, ...] | list[str] = ("bundle",),
        *,
        pylsl: ModuleType | None = None,
    ) -> None:
        if not isinstance(name, str) or not name.strip() or "\0" in name:
            raise OptionError("--lsl-out", f"must be an LSL stream name; got {name!r}")
        lsl = pylsl if pylsl is not None else import_pylsl("--lsl-out")
        info = lsl.StreamInfo(
            name,
            DECISION_TYPE,
            len(DECISION_CHANNELS),
            lsl.IRREGULAR_RATE,
            lsl.cf_double64,
            f"slipkit-{name}",
        )
        desc = info.desc()
        chans = desc.append_child("channels")
        for label in DECISION_CHANNELS:
            chans.append_child("channel").append_child_value("label", label)
        names = desc.append_child("streams")
        for i, s in enumerate(streams):
            names.append_child("stream").append_child_value(
                "index", str(i)
            ).append_child_value("name", s)
        self.name = name
        self.streams = tuple(streams)
        self._outlet = lsl.StreamOutlet(info)
        self._hooks: list[_OutletHook] = []

    def hook(self, stream: int = 0) -> _OutletHook:
        """The :class:`~slipkit.runtime.loop.StreamLoop` ``on_decision`` hook of stream ``stream``.

        liblsl outlets are thread-safe, so the threads of a hand share one outlet.
        """
        h = _OutletHook(self._outlet, stream)
        self._hooks.append(h)
        return h

    @property
    def n_pushed(self) -> int:
        """Decisions pushed, all streams (each hook counts its own)."""
        return sum(h.n_pushed for h in self._hooks)

    def close(self) -> None:
        """Drop the outlet (the stream disappears from the network)."""
        self._outlet = None

    def __enter__(self) -> LslOutlet:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _OutletHook:
    """``on_decision`` for one stream of an :class:`LslOutlet`: one sample per decision.

    Attributes
    ----------
    n_pushed : int
        Decisions this stream pushed.
    """

    def __init__(self, outlet: Any, stream: int) -> None:
        self._push = outlet.push_sample
        self._stream = float(stream)
        self.n_pushed = 0

    def __call__(
        self,
        frame: int,
        timestamp: float,
        score: float,
        klass: int,
        slip: bool,
        declared: bool,
        latency_ns: int,
    ) -> None:
        """Push one decision (its LSL time stamp: the LSL clock now)."""
        self._push(
            [
                self._stream,
                float(frame),
                timestamp,
                score,
                float(klass),
                float(slip),
                float(declared),
                float(latency_ns),
            ]
        )
        self.n_pushed += 1
