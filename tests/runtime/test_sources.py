"""Frame sources: replay files, the UDP frame format, and a loopback round trip."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from tests.runtime.helpers import LinearCase, frames

from slipkit.runtime import (
    FrameError,
    ReplaySource,
    StreamLoop,
    UdpSender,
    UdpSource,
    decode_frame,
    encode_frame,
    load_bundle,
    load_replay,
)
from slipkit.runtime.errors import OptionError
from slipkit.runtime.sources import HEADER_SIZE


@given(
    index=st.integers(0, 2**64 - 1),
    ts=st.floats(allow_nan=False),
    values=arrays(np.float32, st.integers(0, 40), elements=st.floats(width=32)),
)
def test_frame_encoding_round_trips(index: int, ts: float, values: np.ndarray) -> None:
    """Any index, timestamp and float32 values (NaN, inf, empty) survive encode -> decode bit for bit."""
    data = encode_frame(index, ts, values)
    got_index, got_ts, got_values = decode_frame(data)
    assert (index, ts) == (got_index, got_ts)
    assert HEADER_SIZE + 4 * len(values) == len(data)
    np.testing.assert_array_equal(values.view(np.uint32), got_values.view(np.uint32))


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"SLPK", "shorter than the 28-byte header"),
        (b"XXXX" + encode_frame(1, 0.0, [1.0])[4:], "magic"),
        (
            encode_frame(1, 0.0, [1.0])[:4]
            + b"\x02\x00"
            + encode_frame(1, 0.0, [1.0])[6:],
            "version is 2",
        ),
        (encode_frame(1, 0.0, [1.0, 2.0])[:-4], "n_values is 2"),
    ],
)
def test_bad_datagrams_are_named(data: bytes, message: str) -> None:
    """A malformed datagram raises FrameError naming the header field."""
    with pytest.raises(FrameError, match=message):
        decode_frame(data)


def test_udp_loopback_round_trip() -> None:
    """Frames sent to an ephemeral loopback port arrive in order with their index, time and values."""
    x = frames(50)
    ts = np.arange(50) / 100.0
    with (
        UdpSource("127.0.0.1", 0, (3,), max_frames=50, timeout_s=2.0) as src,
        UdpSender(*src.address) as tx,
    ):
        tx.send_all(x, ts)
        got = [(f.frame_index, f.timestamp, f.values.copy()) for f in src]
    assert list(range(50)) == [g[0] for g in got]
    assert ts.tolist() == [g[1] for g in got]
    np.testing.assert_array_equal(x, np.stack([g[2] for g in got]))
    assert (50, 0, 0) == (src.n_received, src.n_rejected, src.n_lost)


def test_udp_counts_lost_rejected_and_times_out() -> None:
    """Index gaps count as lost, wrong-size and late datagrams are skipped, silence ends the stream."""
    with (
        UdpSource("127.0.0.1", 0, (3,), timeout_s=0.2) as src,
        UdpSender(*src.address) as tx,
    ):
        tx.send(0, 0.0, [1, 2, 3])
        tx.send(3, 0.03, [1, 2, 3])  # frames 1 and 2 lost
        tx.send(4, 0.04, [1, 2])  # wrong n_values
        tx.send(2, 0.02, [1, 2, 3])  # late
        tx.send(5, 0.05, [1, 2, 3])
        got = [f.frame_index for f in src]
    assert [0, 3, 5] == got
    # Lost: 1 and 2 (gap), and 4 (arrived malformed, so never decided on).
    assert (3, 2, 3) == (src.n_received, src.n_rejected, src.n_lost)
    assert src.timed_out
    assert "not above the last one" in (src.last_error or "")


def _big_endian_frame(index: int, ts: float, values: list[float]) -> bytes:
    """A frame as a sender writing network byte order would (header and values)."""
    import struct

    head = struct.pack(">4sHHQdI", b"SLPK", 1, 0, index, ts, len(values))
    return head + np.asarray(values, dtype=">f4").tobytes()


def test_big_endian_datagrams_are_rejected_as_such() -> None:
    """A big-endian frame is never read as garbage values: decode_frame and UdpSource
    refuse it naming the byte order; a little-endian frame after it is accepted."""
    data = _big_endian_frame(0, 0.0, [1.0, 2.0, 3.0])
    with pytest.raises(FrameError, match="big-endian datagram"):
        decode_frame(data)
    with (
        UdpSource("127.0.0.1", 0, (3,), timeout_s=0.2) as src,
        UdpSender(*src.address) as tx,
    ):
        tx.sock.sendto(data, src.address)
        tx.send(1, 0.01, [1.0, 2.0, 3.0])
        got = [(f.frame_index, f.values.tolist()) for f in src]
    assert [(1, [1.0, 2.0, 3.0])] == got
    assert 1 == src.n_rejected
    assert "big-endian datagram" in (src.last_error or "")


def test_udp_and_replay_give_the_same_decisions(tmp_path: Path) -> None:
    """The loop decides the same on a UDP stream as on the replay of the same float32 frames."""
    c = LinearCase(tmp_path)
    bundle = load_bundle(c.path)
    replay = StreamLoop(bundle).run(ReplaySource(c.frames, c.timestamps))
    with (
        UdpSource("127.0.0.1", 0, (3,), max_frames=len(c.frames)) as src,
        UdpSender(*src.address) as tx,
    ):
        tx.send_all(c.frames, c.timestamps)
        streamed = StreamLoop(bundle).run(src)
    np.testing.assert_array_equal(replay.declared, streamed.declared)
    np.testing.assert_array_equal(replay.timestamp, streamed.timestamp)


def test_load_replay_npz_and_npy(tmp_path: Path) -> None:
    """An .npz gives its timestamps; an .npy gets index / rate; flat frames are reshaped."""
    x = frames(10)
    np.savez(tmp_path / "r.npz", frames=x, timestamps=np.arange(10) * 0.5)
    np.save(tmp_path / "r.npy", x)
    f1, t1 = load_replay(tmp_path / "r.npz", (3,), 100.0)
    f2, t2 = load_replay(tmp_path / "r.npy", (3, 1), 100.0)
    np.testing.assert_array_equal(x, f1)
    assert (np.arange(10) * 0.5).tolist() == t1.tolist()
    assert (10, 3, 1) == f2.shape
    np.testing.assert_allclose(np.arange(10) / 100.0, t2)


@pytest.mark.parametrize(
    ("arrays_", "message"),
    [
        ({"frames": np.zeros((5, 4))}, r"frames of shape \[4\]"),
        (
            {"frames": np.zeros((5, 3)), "timestamps": np.zeros(4)},
            r"'timestamps' must have shape \(5,\)",
        ),
        ({"frames": np.zeros((3, 3)), "timestamps": [0.0, 2.0, 1.0]}, "non-decreasing"),
        ({"timestamps": np.zeros(4)}, "has no 'frames' array"),
        ({"frames": np.array([["a", "b", "c"]])}, "non-empty numeric"),
    ],
)
def test_bad_replay_is_named(
    tmp_path: Path, arrays_: dict[str, object], message: str
) -> None:
    """A replay with the wrong frame shape, timestamps or arrays is refused naming the array."""
    np.savez(tmp_path / "r.npz", **arrays_)
    with pytest.raises(FrameError, match=message):
        load_replay(tmp_path / "r.npz", (3,), 100.0)


def test_pickled_replay_is_refused(tmp_path: Path) -> None:
    """An object array (which needs pickle) is never loaded."""
    np.save(tmp_path / "r.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(FrameError, match="without pickles"):
        load_replay(tmp_path / "r.npy", (3,), 100.0)


def test_udp_timeout_counts_from_the_first_frame() -> None:
    """Frames sent later than timeout_s after the listener starts are received."""
    with (
        UdpSource("127.0.0.1", 0, (3,), timeout_s=0.2, wait_s=30) as src,
        UdpSender(*src.address) as tx,
    ):
        late = threading.Timer(0.6, tx.send_all, (frames(5), np.arange(5) / 100.0))
        late.start()
        got = [f.frame_index for f in src]
        late.join()
    assert [0, 1, 2, 3, 4] == got
    assert (True, False) == (src.timed_out, src.waited_out)


def test_udp_wait_ends_a_stream_that_never_starts() -> None:
    """With no sender the stream ends after wait_s, marked waited out, not timed out."""
    with UdpSource("127.0.0.1", 0, (3,), timeout_s=30, wait_s=0.2) as src:
        got = list(src)
    assert ([], True, False) == (got, src.waited_out, src.timed_out)


@pytest.mark.parametrize("first_frame", [False, True])
def test_udp_junk_does_not_keep_a_stream_alive(first_frame: bool) -> None:
    """A steady stream of junk datagrams neither extends wait_s nor timeout_s."""
    stop = threading.Event()
    with (
        UdpSource("127.0.0.1", 0, (3,), timeout_s=0.2, wait_s=0.2) as src,
        UdpSender(*src.address) as tx,
    ):

        def junk() -> None:
            for _ in range(500):  # at most ~5 s even if the source never stops
                if stop.is_set():
                    return
                tx.sock.sendto(b"junk", src.address)
                time.sleep(0.01)

        if first_frame:
            tx.send(0, 0.0, [1, 2, 3])
        sender = threading.Thread(target=junk)
        sender.start()
        try:
            got = [f.frame_index for f in src]
        finally:
            stop.set()
            sender.join()
    assert ([0] if first_frame else []) == got
    assert (first_frame, not first_frame) == (src.timed_out, src.waited_out)
    assert "datagram of 4 bytes" in (src.last_error or "")


@pytest.mark.parametrize("wait_s", [-1.0, float("nan"), float("inf"), True])
def test_udp_bad_wait_is_named(wait_s: float) -> None:
    """A wait_s outside [0, one day] (or not a number) is refused naming wait_s."""
    with pytest.raises(OptionError, match="wait_s"):
        UdpSource("127.0.0.1", 0, (3,), wait_s=wait_s)


def test_udp_busy_poll_receives_every_datagram() -> None:
    """A busy-polling UDP source over loopback hands over every frame, in order, values whole."""
    x = frames(200)
    ts = np.arange(200) / 100.0
    with (
        UdpSource("127.0.0.1", 0, (3,), max_frames=200, busy_poll=True) as src,
        UdpSender(*src.address) as tx,
    ):
        sender = threading.Thread(target=tx.send_all, args=(x, ts))
        sender.start()
        got = [(f.frame_index, f.timestamp, f.values.copy()) for f in src]
        sender.join()
    assert list(range(200)) == [g[0] for g in got]
    assert ts.tolist() == [g[1] for g in got]
    np.testing.assert_array_equal(x, np.stack([g[2] for g in got]))
    assert (200, 0, 0) == (src.n_received, src.n_rejected, src.n_lost)


def test_udp_busy_poll_ends_on_wait_and_timeout() -> None:
    """A busy-polling UDP source still ends: wait_s with no sender, timeout_s after the last frame."""
    with UdpSource("127.0.0.1", 0, (3,), wait_s=0.1, busy_poll=True) as idle:
        got_idle = list(idle)
    with (
        UdpSource("127.0.0.1", 0, (3,), timeout_s=0.1, busy_poll=True) as src,
        UdpSender(*src.address) as tx,
    ):
        tx.send_all(frames(3), np.arange(3) / 100.0)
        got = [f.frame_index for f in src]
    assert ([], True, False) == (got_idle, idle.waited_out, idle.timed_out)
    assert ([0, 1, 2], True, False) == (got, src.timed_out, src.waited_out)


def test_udp_busy_poll_junk_does_not_keep_a_stream_alive() -> None:
    """Under busy polling a flood of junk datagrams does not extend wait_s either."""
    stop = threading.Event()
    with (
        UdpSource("127.0.0.1", 0, (3,), wait_s=0.2, busy_poll=True) as src,
        UdpSender(*src.address) as tx,
    ):

        def junk() -> None:
            for _ in range(5000):  # at most ~5 s even if the source never stops
                if stop.is_set():
                    return
                tx.sock.sendto(b"junk", src.address)
                time.sleep(0.001)

        sender = threading.Thread(target=junk)
        sender.start()
        try:
            got = list(src)
        finally:
            stop.set()
            sender.join()
    assert ([], True) == (got, src.waited_out)


def test_lsl_busy_poll_takes_every_sample_and_times_out(tmp_path: Path) -> None:
    """A busy-polling LSL source (stand-in pylsl) hands over every queued sample in order,
    then ends on timeout_s."""
    from tests.runtime.test_lsl import FakePylsl, _fake_sensor

    from slipkit.runtime.lsl import LslSource

    case = LinearCase(tmp_path)
    fake = FakePylsl()
    _fake_sensor(fake, "tactile", case, 50)
    src = LslSource("tactile", (3,), timeout_s=0.1, pylsl=fake, busy_poll=True)
    got = [(f.frame_index, f.timestamp) for f in src]
    assert list(range(50)) == [g[0] for g in got]
    assert case.timestamps[:50].tolist() == [g[1] for g in got]
    assert (50, True) == (src.n_received, src.timed_out)
