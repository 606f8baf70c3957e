"""Decisions out: hand every decision to the grip controller as it is made.

:class:`StreamLoop` calls ``on_decision(frame, timestamp, score, klass, slip,
declared, latency_ns)`` after each decision's latency clock stops; the sinks here
are such callables:

* :class:`UdpSink` sends one datagram per decision (the layout below) from a
  non-blocking socket: a send error (no listener, full buffer) is counted in
  :attr:`UdpSink.n_errors`, never raised and never waited on.
* :class:`JsonlSink` writes one JSON object per decision and line, flushed per line.

:class:`DecisionReceiver` is the matching receiver (a context manager; iterating it
yields :class:`Decision` records until no datagram came for ``timeout_s``).

Datagram layout (version 1), little-endian, 40 bytes, ``struct`` format
``<4sBB2xQdfhBBQ`` (:data:`DECISION_FORMAT`), each field at its natural alignment:

======  =====  ==========  =========================================================
offset  bytes  type        field
======  =====  ==========  =========================================================
0       4      char[4]     magic ``b"SKDC"``
4       1      u8          version, 1
5       1      u8          stream index (0 for a single bundle; a hand's ``--stream`` order)
6       2      (padding)   zero
8       8      u64         frame index (0-based, counted by the loop since its start)
16      8      f64         frame timestamp, s (sensor time; NaN when not given)
24      4      f32         score (the value the decision rule read)
28      2      i16         decided class index (-1: an unclassed threshold rule)
30      1      u8          slip flag of this frame's decision (0 / 1)
31      1      u8          declared (debounced) slip state (0 / 1)
32      8      u64         latency, ns (frame arrival -> decision)
======  =====  ==========  =========================================================

Standard library only (``socket``, ``struct``, ``json``): the runtime's import promise.
"""

from __future__ import annotations

import json
import math
import socket
import struct
import sys
import time
from collections.abc import Iterator
from types import TracebackType
from typing import Any, NamedTuple, TextIO

from slipkit.runtime.errors import FrameError, OptionError

DECISION_MAGIC = b"SKDC"
DECISION_VERSION = 1
# Byte 5 (the stream index) was padding before multi-stream runs: a receiver that
# ignores it reads single-bundle datagrams unchanged.
DECISION_FORMAT = "<4sBB2xQdfhBBQ"
#: Most streams one process can tag (the stream index is one byte).
MAX_STREAMS = 256
_STRUCT = struct.Struct(DECISION_FORMAT)
DECISION_SIZE = _STRUCT.size  # 40 bytes
#: Largest receive wait, s.
MAX_RECEIVE_TIMEOUT_S = 3600.0


class Decision(NamedTuple):
    """One decision record, as sent and received.

    Attributes
    ----------
    frame : int
        Frame index (0-based).
    timestamp : float
        Frame timestamp, s (NaN when the source gave none).
    score : float
        The score the decision rule read (float32 on the wire).
    klass : int
        Decided class index; -1 for an unclassed threshold rule.
    slip : bool
        Whether this frame's decision was slip.
    declared : bool
        Debounced (declared) slip state after this decision.
    latency_ns : int
        Frame arrival -> decision, ns.
    stream : int
        Stream index (0 for a single bundle; in a hand, the ``--stream`` order).
    """

    frame: int
    timestamp: float
    score: float
    klass: int
    slip: bool
    declared: bool
    latency_ns: int
    stream: int = 0


def pack_decision(d: Decision) -> bytes:
    """The datagram of one decision (module docstring: layout version 1)."""
    return _STRUCT.pack(
        DECISION_MAGIC,
        DECISION_VERSION,
        d.stream,
        d.frame,
        d.timestamp,
        d.score,
        d.klass,
        bool(d.slip),
        bool(d.declared),
        d.latency_ns,
    )


def unpack_decision(data: bytes, where: str = "datagram") -> Decision:
    """Parse one datagram; raise :class:`FrameError` naming the field at fault."""
    if len(data) != DECISION_SIZE:
        raise FrameError(
            where, f"size {len(data)} bytes; a decision datagram is {DECISION_SIZE}"
        )
    magic, version, stream, frame, ts, score, klass, slip, decl, lat = _STRUCT.unpack(
        data
    )
    if magic != DECISION_MAGIC:
        raise FrameError(where, f"magic {magic!r}; expected {DECISION_MAGIC!r}")
    if version != DECISION_VERSION:
        raise FrameError(where, f"version {version}; expected {DECISION_VERSION}")
    if slip > 1 or decl > 1:
        raise FrameError(
            where, f"slip / declared bytes {slip} / {decl}; expected 0 or 1"
        )
    return Decision(frame, ts, score, klass, bool(slip), bool(decl), lat, stream)


def parse_address(text: str, option: str, min_port: int = 0) -> tuple[str, int]:
    """``HOST:PORT`` -> (host, port); :class:`OptionError` naming ``option`` otherwise.

    A value that is not ``HOST:PORT`` and a port outside ``[min_port, 65535]`` (0:
    any free port, where a listener may take one) get their own messages.
    """
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isascii() or not port.isdigit():
        raise OptionError(
            option, f"must be HOST:PORT (e.g. 127.0.0.1:9000); got {text!r}"
        )
    if len(port) > 5 or not min_port <= int(port) <= 65535:
        raise OptionError(
            option,
            f"port {port[:12]}{'...' if len(port) > 12 else ''} is out of range: "
            f"a port is in [{min_port}, 65535]; got {text[:80]!r}",
        )
    return host, int(port)


class UdpSink:
    """Send each decision as one datagram to ``host:port`` without ever blocking.

    Parameters
    ----------
    host, port : str, int
        Where the grip controller listens (port 1-65535).
    stream : int
        Stream index written into every datagram (byte 5), in [0, 255]; a hand
        gives each stream its own sink with its index.

    Attributes
    ----------
    n_sent : int
        Datagrams handed to the kernel.
    n_errors : int
        Sends that failed (no route, refused by an absent listener, buffer full);
        the decision is dropped, the loop goes on.
    last_error : str or None
        The latest send error.
    """

    def __init__(self, host: str, port: int, *, stream: int = 0) -> None:
        if not 0 < port <= 65535:
            raise OptionError("port", f"must be in [1, 65535]; got {port}")
        if not 0 <= stream < MAX_STREAMS:
            raise OptionError(
                "stream", f"must be in [0, {MAX_STREAMS - 1}]; got {stream}"
            )
        self.stream = int(stream)
        try:
            infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except (OSError, UnicodeError, ValueError) as exc:  # ValueError: a NUL
            raise OptionError("host", f"cannot resolve {host!r}: {exc}") from None
        family, kind, proto, _, addr = infos[0]
        self._sock = socket.socket(family, kind, proto)
        self._sock.setblocking(False)
        try:
            # connect() on UDP only fixes the peer: send() then skips the address
            # lookup per datagram.
            self._sock.connect(addr)
        except OSError as exc:
            self._sock.close()
            raise OptionError("host", f"cannot send to {host}:{port}: {exc}") from None
        self.where = f"udp {host}:{port}"
        # One preallocated buffer, packed in place per decision.
        self._buf = bytearray(DECISION_SIZE)
        self._pack_into = _STRUCT.pack_into
        self._send = self._sock.send
        self.n_sent = 0
        self.n_errors = 0
        self.last_error: str | None = None

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
        """Pack and send one decision (the :class:`StreamLoop` ``on_decision`` hook)."""
        try:
            self._pack_into(
                self._buf,
                0,
                DECISION_MAGIC,
                DECISION_VERSION,
                self.stream,
                frame,
                timestamp,
                score,
                klass,
                slip,
                declared,
                latency_ns,
            )
            self._send(self._buf)
        # OSError: BlockingIOError, ConnectionRefusedError, ...; struct.error /
        # OverflowError: a score beyond float32 or a class beyond i16.
        except (OSError, struct.error, OverflowError) as exc:
            self.n_errors += 1
            self.last_error = exc.__class__.__name__
        else:
            self.n_sent += 1

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()

    def __enter__(self) -> UdpSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class JsonlSink:
    """Write each decision as one JSON object per line, flushed per line.

    Keys: ``frame``, ``t`` (s, null when not given), ``score``, ``class`` (index,
    null for an unclassed threshold rule), ``slip``, ``declared``, ``latency_ns``;
    with a ``label``, first ``stream`` (the label).

    Parameters
    ----------
    stream : text file, optional
        Where to write (default: ``sys.stdout`` at call time).
    label : str, optional
        The stream's name, written as the ``stream`` key (a hand's streams share stdout).
    lock : lock, optional
        Held while a line is written, so the threads of a hand cannot interleave lines.
    """

    def __init__(
        self,
        stream: TextIO | None = None,
        *,
        label: str | None = None,
        lock: Any | None = None,
    ) -> None:
        self._stream = stream
        self._head = {} if label is None else {"stream": label}
        self._lock = lock

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
        """Write one decision line (the :class:`StreamLoop` ``on_decision`` hook)."""
        out = self._stream or sys.stdout
        line = (
            json.dumps(
                {
                    **self._head,
                    "frame": frame,
                    "t": None if math.isnan(timestamp) else timestamp,
                    "score": score if math.isfinite(score) else None,
                    "class": None if klass < 0 else klass,
                    "slip": bool(slip),
                    "declared": bool(declared),
                    "latency_ns": latency_ns,
                }
            )
            + "\n"
        )
        if self._lock is None:
            out.write(line)
            out.flush()
            return
        with self._lock:
            out.write(line)
            out.flush()


class Fanout:
    """Call several ``on_decision`` sinks in order (one hook for the loop)."""

    def __init__(self, *sinks: Any) -> None:
        self._sinks = tuple(sinks)

    def __call__(self, *record: Any) -> None:
        """Hand the record to every sink."""
        for sink in self._sinks:
            sink(*record)


class DecisionReceiver:
    """Receive decision datagrams (the grip controller's side, or a test's).

    Parameters
    ----------
    host : str
        Address to bind (default ``127.0.0.1``).
    port : int
        Port to bind; 0 picks a free one (:attr:`port` says which).
    timeout_s : float
        Iteration ends when no datagram arrived for this long, s (wall clock).
    max_records : int, optional
        Iteration ends after this many records.

    Attributes
    ----------
    port : int
        The bound port.
    n_rejected : int
        Datagrams that were not decision records (wrong size, magic or version).

    Examples
    --------
    >>> with DecisionReceiver(port=0, timeout_s=0.01) as rx:  # doctest: +SKIP
    ...     for d in rx:
    ...         print(d.frame, d.declared)
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        timeout_s: float = 1.0,
        max_records: int | None = None,
    ) -> None:
        if not 0 < timeout_s <= MAX_RECEIVE_TIMEOUT_S:  # False for NaN too
            raise OptionError(
                "timeout_s",
                f"must be in (0, {MAX_RECEIVE_TIMEOUT_S:g}] s; got {timeout_s}",
            )
        self.timeout_s = float(timeout_s)
        self.max_records = max_records
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            # Room for bursts: a replay sends its decisions faster than real time.
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise OptionError("port", f"cannot bind {host}:{port}: {exc}") from None
        self.host = host
        self.port = int(self._sock.getsockname()[1])
        self.n_rejected = 0

    def __iter__(self) -> Iterator[Decision]:
        n = 0
        deadline = time.monotonic() + self.timeout_s
        where = f"udp {self.host}:{self.port}"
        while self.max_records is None or n < self.max_records:
            left = deadline - time.monotonic()
            if left <= 0:
                return
            self._sock.settimeout(left)
            try:
                data = self._sock.recv(DECISION_SIZE + 1)
            except TimeoutError:
                return
            try:
                d = unpack_decision(data, where)
            except FrameError:
                self.n_rejected += 1
                continue
            n += 1
            deadline = time.monotonic() + self.timeout_s
            yield d

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()

    def __enter__(self) -> DecisionReceiver:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
