"""Frame sources for the loop: recorded replays and a UDP stream on loopback.

Every source yields :class:`Frame` tuples ``(frame_index, timestamp, values, arrival_ns)``;
``arrival_ns`` is :func:`time.perf_counter_ns` when the frame was handed over (for UDP:
right after the datagram was received), so the loop's latency runs from arrival to
decision.

Replay files
------------
``.npz`` (what exporters put in a bundle as ``replay.npz``): ``frames`` of shape
``(n, *frame.shape)`` (or ``(n, n_values)``) and ``timestamps`` of shape ``(n,)`` in s,
non-decreasing; read with numpy's ``.npy`` header reader, never a pickle, every size
checked before anything is allocated (:func:`load_replay`). ``.npy``: ``frames`` only; the
timestamps are ``index / frame.rate_hz``.

UDP frame format (version 1)
----------------------------
One frame per datagram, little-endian::

    offset  size  type      field
    0       4     bytes     magic b"SLPK"
    4       2     uint16    version (1)
    6       2     uint16    flags (0; reserved)
    8       8     uint64    frame index (increasing; gaps count as lost frames)
    16      8     float64   timestamp, s (sensor clock)
    24      4     uint32    n_values
    28      4*n   float32   values, C order of frame.shape (channel order of the manifest)

The whole datagram is little-endian, the values included (``<f4``). The version
field doubles as a byte-order mark: a datagram written big-endian (``struct`` format
``">4sHHQdI"`` or ``"!..."``, a big-endian host's native order) reads version 256,
and is rejected as big-endian by name. (Big-endian values behind a little-endian
header cannot be told from other values: a sender writes both in one order.)

A datagram that breaks the format, has the wrong ``n_values`` or an index not above the
last one is skipped and counted in :attr:`UdpSource.n_rejected` (a live loop must not
stop on one bad packet); the last reason is kept in :attr:`UdpSource.last_error`.

Resynchronisation: after ``resync_after`` (default 8) *consecutive* well-formed
datagrams whose index is not above the last accepted one, the next such datagram is
accepted as the start of a new sequence (:attr:`UdpSource.n_resyncs` counts these),
so a sensor bridge that restarts at index 0, or one stray datagram with index
2^64 - 1, costs ``resync_after`` frames instead of the rest of the run. A forward
jump of more than :data:`MAX_LOST_JUMP` frames is also a resync, not that many lost
frames. Two clocks bound a run, both on the wall clock and both reset by *accepted*
frames only (junk datagrams do not keep a run alive): ``wait_s`` bounds the wait for
the first frame (a listener is usually started before the sensor), ``timeout_s`` the
silence after any accepted frame.
"""

from __future__ import annotations

import math
import socket
import struct
import time
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import IO, NamedTuple, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slipkit.runtime.errors import FrameError, OptionError

MAGIC = b"SLPK"
VERSION = 1
#: magic, version, flags, frame index, timestamp (s), n_values.
HEADER = struct.Struct("<4sHHQdI")
HEADER_SIZE = HEADER.size  # 28 bytes
#: Default run of consecutive out-of-order datagrams after which a UDP source resyncs.
RESYNC_AFTER = 8
#: Most consecutive out-of-order datagrams ``resync_after`` may ask for.
MAX_RESYNC_AFTER = 1_000_000
#: A forward index jump above this many frames is a resync, not lost frames.
MAX_LOST_JUMP = 1 << 20
#: Longest UDP timeout or first-frame wait, s (one day).
MAX_TIMEOUT_S = 86_400.0
#: Default wait for the first UDP frame, s: long enough to start the sensor by hand.
DEFAULT_WAIT_S = 30.0
#: Largest replay array read (bytes, uncompressed): 1 GiB.
MAX_REPLAY_BYTES = 1 << 30


class Frame(NamedTuple):
    """One sensor frame as a source hands it to the loop.

    Attributes
    ----------
    frame_index : int
        Frame index (replay: row number; UDP: the sender's index).
    timestamp : float
        Sensor time, s.
    values : ndarray of shape frame.shape
        The values; for UDP a view of the receive buffer, valid until the next
        frame is read (the loop copies it into its ring buffer at once).
    arrival_ns : int
        :func:`time.perf_counter_ns` at hand-over.
    """

    frame_index: int
    timestamp: float
    values: NDArray[np.floating]
    arrival_ns: int


def encode_frame(index: int, timestamp: float, values: ArrayLike) -> bytes:
    """One frame as a version-1 datagram (see the module docstring)."""
    arr = np.ascontiguousarray(values, dtype="<f4").reshape(-1)
    return (
        HEADER.pack(MAGIC, VERSION, 0, int(index), float(timestamp), arr.size)
        + arr.tobytes()
    )


#: The version as a big-endian sender's header reads here (the byte-order mark).
SWAPPED_VERSION = int.from_bytes(VERSION.to_bytes(2, "little"), "big")


def _header_problem(magic: bytes, version: int, n_values: int, want: int) -> str:
    """Why a header is refused (a big-endian one named as such)."""
    if magic == MAGIC and version == SWAPPED_VERSION:
        return (
            f"big-endian datagram (version reads {version}, {VERSION} byte-swapped): "
            "the frame format is little-endian, header and '<f4' values"
        )
    return (
        f"header magic={magic!r} version={version} n_values={n_values}; expected "
        f"{MAGIC!r}, {VERSION}, {want}"
    )


def decode_frame(
    data: bytes, where: str = "udp frame"
) -> tuple[int, float, NDArray[np.float32]]:
    """Parse a version-1 datagram into ``(index, timestamp, values)``.

    Raises
    ------
    FrameError
        Naming the header field that is wrong.
    """
    if len(data) < HEADER_SIZE:
        raise FrameError(
            where, f"{len(data)} bytes is shorter than the {HEADER_SIZE}-byte header"
        )
    magic, version, _flags, index, ts, n = HEADER.unpack_from(data)
    if magic == MAGIC and version == SWAPPED_VERSION:
        raise FrameError(where, _header_problem(magic, version, n, n))
    if magic != MAGIC:
        raise FrameError(where, f"magic is {magic!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise FrameError(where, f"version is {version}, this runtime reads {VERSION}")
    if len(data) != HEADER_SIZE + 4 * n:
        raise FrameError(
            where,
            f"n_values is {n} but the payload holds {(len(data) - HEADER_SIZE) / 4:g} float32 values",
        )
    return index, ts, np.frombuffer(data, dtype="<f4", count=n, offset=HEADER_SIZE)


def check_replay_arrays(
    frames: np.ndarray, timestamps: np.ndarray, frame_shape: tuple[int, ...], where: str
) -> tuple[NDArray[np.floating], NDArray[np.float64]]:
    """Check recorded frames and timestamps against a frame shape.

    Returns ``frames`` as ``(n, *frame_shape)`` (float32 kept, other numbers as
    float64) and ``timestamps`` as float64 (integer or float arrays only: strings
    and booleans are refused, not converted); :class:`FrameError` names the array.
    """
    if frames.dtype.kind not in "fiu" or frames.ndim < 2 or len(frames) == 0:
        raise FrameError(
            where,
            f"'frames' must be a non-empty numeric array (n, *frame shape); got {frames.dtype} {frames.shape}",
        )
    n = len(frames)
    if frames.shape[1:] != tuple(frame_shape):
        if math.prod(frames.shape[1:]) != math.prod(frame_shape):
            raise FrameError(
                where,
                f"'frames' has frames of shape {list(frames.shape[1:])}; the bundle's frame.shape is {list(frame_shape)}",
            )
        frames = frames.reshape(n, *frame_shape)
    if frames.dtype != np.float32:
        frames = frames.astype(np.float64)
    if timestamps.dtype.kind not in "fiu":
        # strings or booleans would convert silently; a replay stores numbers
        raise FrameError(
            where,
            f"'timestamps' must be numbers (s); got dtype {timestamps.dtype}",
        )
    times = np.asarray(timestamps, dtype=np.float64)
    if times.shape != (n,):
        raise FrameError(
            where,
            f"'timestamps' must have shape ({n},), one per frame; got {times.shape}",
        )
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) < 0):
        raise FrameError(where, "'timestamps' must be finite and non-decreasing (s)")
    return frames, times


_NPY_MAGIC = b"\x93NUMPY"
_ZIP_MAGIC = b"PK\x03\x04"
#: What reading a damaged replay can raise: zipfile's BadZipFile, EOFError and
#: zlib.error on a damaged member, NotImplementedError for an unknown compression,
#: RuntimeError for an encrypted member; numpy's header parser a ValueError.
_READ_ERRORS = (
    OSError,
    ValueError,
    EOFError,
    zipfile.BadZipFile,
    zlib.error,
    NotImplementedError,
    RuntimeError,
    struct.error,
)


def _read_npy(fp: IO[bytes], available: int, what: str, max_bytes: int) -> np.ndarray:
    """One ``.npy`` array from ``fp``, its size checked before anything is allocated.

    ``available`` is the number of bytes ``fp`` holds (the file size, or a zip
    member's uncompressed size). numpy's own header reader is used; the data size
    the header claims (shape x itemsize) must fit in ``available`` and ``max_bytes``.
    """
    version = np.lib.format.read_magic(fp)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(fp)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(fp)
    else:
        raise ValueError(f"{what}: .npy format version {version} is not read here")
    if dtype.hasobject:
        raise ValueError(f"{what}: holds Python objects, which only a pickle can load")
    nbytes = math.prod(shape) * dtype.itemsize
    if nbytes > max_bytes:
        raise ValueError(
            f"{what}: its header claims shape {list(shape)} of {dtype} = {nbytes} "
            f"bytes; at most {max_bytes} are read"
        )
    header = fp.tell()
    if nbytes > available - header:
        raise ValueError(
            f"{what}: its header claims shape {list(shape)} of {dtype} = {nbytes} "
            f"bytes but only {max(available - header, 0)} follow (truncated?)"
        )
    data = fp.read(nbytes)
    if len(data) != nbytes:
        raise ValueError(f"{what}: ended after {len(data)} of {nbytes} data bytes")
    arr = np.frombuffer(data, dtype=dtype)
    return arr.reshape(shape, order="F" if fortran else "C")


def load_replay(
    path: str | Path,
    frame_shape: tuple[int, ...],
    rate_hz: float,
    *,
    max_bytes: int = MAX_REPLAY_BYTES,
) -> tuple[NDArray[np.floating], NDArray[np.float64]]:
    """Read a ``.npz`` (frames + timestamps) or ``.npy`` (frames) replay file.

    Sizes are checked before anything is allocated: the file itself, each ``.npz``
    member's uncompressed size (``ZipInfo.file_size``, so a zip bomb is refused
    unopened) and the data size each ``.npy`` header claims, against ``max_bytes``
    and against the bytes actually there. Object arrays (pickles) are refused.

    Parameters
    ----------
    path : str or Path
        The file.
    frame_shape : tuple of int
        The bundle's ``frame.shape``.
    rate_hz : float
        Frame rate, Hz, for the timestamps of a ``.npy`` file.
    max_bytes : int
        Largest file, member and array read, bytes (default 1 GiB).

    Returns
    -------
    frames : ndarray of shape (n, *frame_shape)
    timestamps : ndarray of shape (n,), s

    Raises
    ------
    FrameError
        Naming the file (and the member or array) and what is wrong.
    """
    p = Path(path)
    where = str(p)
    if not p.is_file():
        raise FrameError(where, "replay file not found")
    times: np.ndarray | None = None
    try:
        size = p.stat().st_size
        # A header or a zip directory may add a little to the array's own bytes.
        if size > max_bytes + (1 << 20):
            raise ValueError(f"is {size} bytes; at most {max_bytes} are read")
        with open(p, "rb") as fh:
            magic = fh.read(6)
            fh.seek(0)
            if magic == _NPY_MAGIC:
                frames = _read_npy(fh, size, "the .npy file", max_bytes)
            elif magic.startswith(_ZIP_MAGIC):
                with zipfile.ZipFile(fh) as zf:
                    members = {
                        n[:-4]: zf.getinfo(n)
                        for n in zf.namelist()
                        if n.endswith(".npy")
                    }
                    if "frames" not in members:
                        raise ValueError(
                            f"has no 'frames' array; arrays: {sorted(members)[:10]}"
                        )
                    arrays = {}
                    for key in ("frames", "timestamps"):
                        info = members.get(key)
                        if info is None:
                            continue
                        what = f"member {info.filename!r}"
                        if info.file_size > max_bytes + (1 << 20):
                            raise ValueError(
                                f"{what} unpacks to {info.file_size} bytes; at most "
                                f"{max_bytes} are read (a zip bomb?)"
                            )
                        with zf.open(info) as member:
                            arrays[key] = _read_npy(
                                member, info.file_size, what, max_bytes
                            )
                    frames = arrays["frames"]
                    times = arrays.get("timestamps")
            else:
                raise ValueError(
                    f"is neither a .npz (zip) nor a .npy file (starts with {magic!r})"
                )
    except _READ_ERRORS as exc:
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise FrameError(
            where, f"not a numpy .npz/.npy file without pickles: {text}"
        ) from None
    if times is None:
        n = len(frames) if frames.ndim else 0
        times = np.arange(n, dtype=np.float64) / rate_hz
    return check_replay_arrays(frames, times, frame_shape, where)


class ReplaySource:
    """Recorded frames handed to the loop as fast as it takes them.

    Parameters
    ----------
    frames : ndarray of shape (n, *frame.shape)
        The frames.
    timestamps : ndarray of shape (n,)
        Their times, s.
    """

    def __init__(
        self, frames: NDArray[np.floating], timestamps: NDArray[np.float64]
    ) -> None:
        self.frames = frames
        self.timestamps = timestamps

    @classmethod
    def from_file(
        cls, path: str | Path, frame_shape: tuple[int, ...], rate_hz: float
    ) -> ReplaySource:
        """A source over a replay file (see :func:`load_replay`)."""
        return cls(*load_replay(path, frame_shape, rate_hz))

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self) -> Iterator[Frame]:
        clock = time.perf_counter_ns
        for i, (values, ts) in enumerate(
            zip(self.frames, self.timestamps.tolist(), strict=True)
        ):
            yield Frame(i, ts, values, clock())


_S = TypeVar("_S", bound="_Socket")


class _Socket:
    """A UDP socket held in ``self.sock``, closed by :meth:`close` or a ``with`` block."""

    sock: socket.socket

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()

    def __enter__(self: _S) -> _S:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class UdpSource(_Socket):
    """Frames received as version-1 datagrams on a UDP socket.

    Parameters
    ----------
    host : str
        Address to bind (``127.0.0.1`` for loopback).
    port : int
        Port to bind; 0 picks a free one (see :attr:`address`).
    frame_shape : tuple of int
        The bundle's ``frame.shape``: datagrams must carry ``prod(frame_shape)`` values.
    max_frames : int, optional
        Stop after this many accepted frames.
    timeout_s : float
        After the first accepted frame, stop when no frame has been *accepted* for
        this long, s, on the wall clock (junk datagrams do not reset it); in
        (0, :data:`MAX_TIMEOUT_S`].
    wait_s : float
        Stop when no frame has been accepted this long, s, after the iteration
        started (the wait for the first frame; junk does not end it); 0 waits
        forever; in [0, :data:`MAX_TIMEOUT_S`]. Default :data:`DEFAULT_WAIT_S`.
    resync_after : int
        Consecutive out-of-order datagrams after which the next one starts a new
        sequence (module docstring); in [1, :data:`MAX_RESYNC_AFTER`].
    busy_poll : bool
        Iteration reads the socket without blocking, over and over, instead of
        sleeping in ``recv`` until a datagram comes: the thread never sleeps, so its
        core stays hot (caches, TLB, no idle-state exit) and a frame is read within
        a few microseconds of landing, at the price of one core kept 100 % busy
        (``slipkit-run --busy-poll``; pair it with ``--cpus``). ``timeout_s`` and
        ``wait_s`` end it as they end a blocking iteration; Ctrl-C interrupts it.

    Attributes
    ----------
    address : tuple of (str, int)
        The bound address.
    n_received, n_rejected, n_lost : int
        Accepted datagrams, skipped datagrams, and frames missing from gaps in the index.
    n_resyncs : int
        Times the index sequence was restarted (a run of ``resync_after``
        out-of-order datagrams, or a forward jump above :data:`MAX_LOST_JUMP`).
    timed_out : bool
        The stream ended because nothing was accepted within ``timeout_s`` of the
        last accepted frame.
    waited_out : bool
        The stream ended because no frame was accepted within ``wait_s``.
    ended : bool
        :meth:`poll` has nothing more to give (``max_frames`` reached or a deadline
        passed).
    last_error : str or None
        Why the last datagram was rejected.

    Raises
    ------
    OptionError
        ``timeout_s``, ``wait_s``, ``resync_after`` or ``max_frames`` out of range, or the
        address cannot be bound (naming ``host``).
    """

    def __init__(
        self,
        host: str,
        port: int,
        frame_shape: tuple[int, ...],
        *,
        max_frames: int | None = None,
        timeout_s: float = 2.0,
        wait_s: float = DEFAULT_WAIT_S,
        resync_after: int = RESYNC_AFTER,
        busy_poll: bool = False,
    ) -> None:
        if not (
            isinstance(timeout_s, int | float)
            and not isinstance(timeout_s, bool)
            and 0 < timeout_s <= MAX_TIMEOUT_S
        ):
            raise OptionError(
                "timeout_s", f"must be in (0, {MAX_TIMEOUT_S:g}] s; got {timeout_s!r}"
            )
        if not (
            isinstance(wait_s, int | float)
            and not isinstance(wait_s, bool)
            and 0 <= wait_s <= MAX_TIMEOUT_S  # False for NaN too
        ):
            raise OptionError(
                "wait_s",
                f"must be in [0, {MAX_TIMEOUT_S:g}] s (0: forever); got {wait_s!r}",
            )
        if not (
            isinstance(resync_after, int)
            and not isinstance(resync_after, bool)
            and 1 <= resync_after <= MAX_RESYNC_AFTER
        ):
            raise OptionError(
                "resync_after",
                f"must be an integer in [1, {MAX_RESYNC_AFTER}]; got {resync_after!r}",
            )
        if max_frames is not None and not (
            isinstance(max_frames, int) and max_frames >= 1
        ):
            raise OptionError("max_frames", f"must be >= 1; got {max_frames!r}")
        self.frame_shape = tuple(frame_shape)
        self.n_values = math.prod(self.frame_shape)
        self.max_frames = max_frames
        self.timeout_s = float(timeout_s)
        self.wait_s = float(wait_s)
        self.resync_after = resync_after
        self.busy_poll = bool(busy_poll)
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise OptionError("port", f"must be an integer in [0, 65535]; got {port!r}")
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            # A larger receive queue rides out a burst while the loop runs the model.
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            self.sock.bind((host, port))
        except (OSError, UnicodeError, TypeError) as exc:
            self.sock.close()
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise OptionError(
                "host", f"cannot listen on {host!r} port {port}: {why}"
            ) from None
        self.address: tuple[str, int] = self.sock.getsockname()
        self.where = f"udp {self.address[0]}:{self.address[1]}"
        self.expected = HEADER_SIZE + 4 * self.n_values
        # One byte more than a valid datagram, so an oversized one shows up as too long.
        self._buf = bytearray(self.expected + 1)
        self._values = np.frombuffer(
            self._buf, dtype="<f4", count=self.n_values, offset=HEADER_SIZE
        ).reshape(self.frame_shape)
        self.n_received = self.n_rejected = self.n_lost = self.n_resyncs = 0
        self.timed_out = self.waited_out = False
        self.last_error: str | None = None
        self._start()

    def _expire(self) -> None:
        if self.n_received:
            self.timed_out = True
        else:
            self.waited_out = True

    def _reject(self, problem: str) -> None:
        self.n_rejected += 1
        self.last_error = problem

    def _start(self) -> None:
        """Reset the index sequence and start the wait clock (a new iteration or poll)."""
        self._last = -1
        self._out_of_order = (
            0  # consecutive well-formed datagrams with an index <= last
        )
        # Before the first accepted frame the deadline is ``wait_s`` from the start
        # (None: forever), after it ``timeout_s`` from the last accepted frame; both on
        # the wall clock, so a stream of junk datagrams cannot keep the run alive.
        self._deadline: float | None = (
            None if self.wait_s == 0 else time.monotonic() + self.wait_s
        )
        self.ended = False

    def _admit(self, n: int, arrival: int) -> Frame | None:
        """Check the ``n``-byte datagram in the buffer: the frame, or None when rejected."""
        if n != self.expected:
            self._reject(
                f"datagram of {n} bytes; a frame of {self.n_values} values is {self.expected}"
            )
            return None
        magic, version, _flags, index, ts, nv = HEADER.unpack_from(self._buf)
        if magic != MAGIC or version != VERSION or nv != self.n_values:
            self._reject(_header_problem(magic, version, nv, self.n_values))
            return None
        last = self._last
        if index <= last:
            if self._out_of_order < self.resync_after:
                self._out_of_order += 1
                self._reject(
                    f"frame index {index} is not above the last one ({last}): "
                    "late or repeated"
                )
                return None
            self.n_resyncs += 1  # a sender that restarted its count
        elif last >= 0:
            if index - last - 1 > MAX_LOST_JUMP:
                self.n_resyncs += 1  # a jump, not that many lost frames
            else:
                self.n_lost += index - last - 1
        self._out_of_order = 0
        self._last = index
        self.n_received += 1
        self._deadline = time.monotonic() + self.timeout_s
        return Frame(index, ts, self._values, arrival)

    def __iter__(self) -> Iterator[Frame]:
        if self.busy_poll:
            yield from self._iter_busy()
            return
        recv_into, clock, buf = self.sock.recv_into, time.perf_counter_ns, self._buf
        settimeout, now, admit = self.sock.settimeout, time.monotonic, self._admit
        self._start()
        while self.max_frames is None or self.n_received < self.max_frames:
            deadline = self._deadline
            if deadline is not None:
                left = deadline - now()
                if left <= 0:
                    self._expire()
                    return
                settimeout(left)
            else:
                settimeout(None)
            try:
                n = recv_into(buf)
            except TimeoutError:
                self._expire()
                return
            frame = admit(n, clock())
            if frame is not None:
                yield frame

    def _iter_busy(self) -> Iterator[Frame]:
        """Iteration without sleeping: non-blocking reads in a loop (``busy_poll``)."""
        self.sock.setblocking(False)
        recv_into, clock, buf = self.sock.recv_into, time.perf_counter_ns, self._buf
        now, admit = time.monotonic, self._admit
        self._start()
        while self.max_frames is None or self.n_received < self.max_frames:
            try:
                frame = admit(recv_into(buf), clock())
            except (BlockingIOError, InterruptedError):
                frame = None
            if frame is not None:
                yield frame
                continue
            # Nothing queued (or junk, which does not keep a run alive): check the
            # deadline (a monotonic read, well under a microsecond) and spin.
            deadline = self._deadline
            if deadline is not None and now() > deadline:
                self._expire()
                return

    def start_polling(self) -> None:
        """Make the socket non-blocking and start the wait clock, for :meth:`poll`."""
        self.sock.setblocking(False)
        self._start()

    def poll(self, max_reads: int = 64) -> Frame | None:
        """The next accepted frame if one is queued, else None; never blocks.

        For a loop that serves several sources in one thread (:mod:`slipkit.runtime.hand`):
        call :meth:`start_polling` once, then ``poll`` whenever the socket is readable
        or a deadline may have passed. At most ``max_reads`` datagrams are read per
        call, so a flood of junk on this socket cannot hold the loop from another
        source. Sets :attr:`ended` (and :attr:`timed_out` or :attr:`waited_out`) when
        ``max_frames`` were accepted or a deadline passed.
        """
        if self.ended:
            return None
        if self.max_frames is not None and self.n_received >= self.max_frames:
            self.ended = True
            return None
        recv_into, buf = self.sock.recv_into, self._buf
        for _ in range(max_reads):
            try:
                n = recv_into(buf)
            except (BlockingIOError, InterruptedError):
                break
            frame = self._admit(n, time.perf_counter_ns())
            if frame is not None:
                return frame
        if self._deadline is not None and time.monotonic() > self._deadline:
            self._expire()
            self.ended = True
        return None


class UdpSender(_Socket):
    """Sends frames as version-1 datagrams (tests, docs, and a sensor bridge's model).

    Parameters
    ----------
    host, port : str, int
        Where the loop's :class:`UdpSource` listens.
    """

    def __init__(self, host: str, port: int) -> None:
        self.address = (host, port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(self, index: int, timestamp: float, values: ArrayLike) -> None:
        """Send one frame (index, timestamp in s, values in manifest channel order)."""
        self.sock.sendto(encode_frame(index, timestamp, values), self.address)

    def send_all(
        self, frames: ArrayLike, timestamps: ArrayLike, *, pace_s: float = 0.0
    ) -> None:
        """Send frames ``0..n-1``; ``pace_s`` sleeps between frames (0: as fast as possible)."""
        arr = np.asarray(frames)
        for i, ts in enumerate(np.asarray(timestamps, dtype=np.float64).tolist()):
            self.send(i, ts, arr[i])
            if pace_s:
                time.sleep(pace_s)
