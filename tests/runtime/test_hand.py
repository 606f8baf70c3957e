"""A whole hand in one process: ``slipkit-run --stream``, stream parsing, scheduling and isolation."""

from __future__ import annotations

import argparse
import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from tests.runtime.helpers import LinearCase

from slipkit.runtime import load_bundle
from slipkit.runtime.cli import _busy_poll_notes, main, run
from slipkit.runtime.errors import OptionError
from slipkit.runtime.hand import (
    HandStream,
    ReplayFeed,
    StreamBinding,
    check_bindings,
    parse_stream,
    run_streams,
)
from slipkit.runtime.loop import StreamLoop
from slipkit.runtime.realtime import RealtimeOptions
from slipkit.runtime.sinks import DecisionReceiver
from slipkit.runtime.sources import ReplaySource, UdpSender, UdpSource


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[LinearCase, LinearCase]:
    """Two linear bundles (different weights) with their replays, generous budgets."""
    root = tmp_path_factory.mktemp("hand")
    budget = (10_000.0, 10_000.0)
    return (
        LinearCase(root, name="a", seed=0, budget=budget),
        LinearCase(root, name="b", seed=1, budget=budget),
    )


def _alone_scores(case: LinearCase) -> np.ndarray:
    loop = StreamLoop(load_bundle(case.path))
    return loop.run(ReplaySource(case.frames, case.timestamps)).score


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("thumb=exports/a", StreamBinding("thumb", Path("exports/a"))),
        (
            "palm=b@replay:x.npz",
            StreamBinding("palm", Path("b"), "replay", "x.npz"),
        ),
        (
            "index=/p/q@udp:0.0.0.0:9001",
            StreamBinding("index", Path("/p/q"), "udp", "0.0.0.0:9001"),
        ),
        (
            "tip=b@lsl:BioTac@1",
            StreamBinding("tip", Path("b"), "lsl", "BioTac@1"),
        ),
    ],
)
def test_parse_stream_reads_name_bundle_and_source(
    text: str, expected: StreamBinding
) -> None:
    """NAME=BUNDLE[@kind:target] splits at the first source marker."""
    assert expected == parse_stream(text)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("nobundle", "NAME=BUNDLE"),
        ("bad name=b", "stream name 'bad name'"),
        ("a=b@udp:", "needs a target"),
        ("a=@udp:1.2.3.4:5", "no bundle folder"),
        ("a=b@udp:9000", "HOST:PORT"),
        ("a=B@bogus:xyz", "unknown source kind 'bogus'"),
        ("a=b@udp:127.0.0.1:70000", "port 70000 is out of range"),
    ],
)
def test_parse_stream_names_what_is_wrong(text: str, fragment: str) -> None:
    """A malformed --stream is an OptionError naming the part at fault."""
    with pytest.raises(OptionError, match="--stream") as info:
        parse_stream(text)
    assert fragment in str(info.value)


def test_duplicate_stream_names_are_refused() -> None:
    """Two streams with one name are an error naming the name."""
    b = [StreamBinding("x", Path("a")), StreamBinding("x", Path("b"))]
    with pytest.raises(OptionError, match="'x' is given twice"):
        check_bindings(b)


@pytest.mark.parametrize("mode", ["loop", "threads"])
def test_each_stream_decides_as_its_bundle_alone(
    pair: tuple[LinearCase, LinearCase], tmp_path: Path, mode: str
) -> None:
    """Two replay streams in one process give each bundle's own scores, reported per stream."""
    a, b = pair
    out = tmp_path / "hand.json"
    status = run(
        [
            "--stream",
            f"thumb={a.path}",
            "--stream",
            f"palm={b.path}@replay:{b.path / 'replay.npz'}",
            "--hand-mode",
            mode,
            "--check",
            "--json",
            str(out),
        ]
    )
    summary = json.loads(out.read_text())
    rows = {s["stream"]: s for s in summary["streams"]}
    assert 0 == status
    assert ["thumb", "palm"] == summary["hand"]["streams"]
    assert [197, 197] == [rows["thumb"]["decisions"], rows["palm"]["decisions"]]
    assert [True, True] == [
        rows["thumb"]["within_budget"],
        rows["palm"]["within_budget"],
    ]


def _hand(
    cases: list[LinearCase], sources: list[object], names: list[str]
) -> list[HandStream]:
    out = []
    for i, (case, src, name) in enumerate(zip(cases, sources, names, strict=True)):
        bundle = load_bundle(case.path)
        out.append(
            HandStream(
                i, StreamBinding(name, case.path), bundle, StreamLoop(bundle), src
            )
        )
    return out


@pytest.mark.parametrize("mode", ["loop", "threads"])
def test_paced_replays_keep_their_scores(
    pair: tuple[LinearCase, LinearCase], mode: str
) -> None:
    """Pacing replays at their timestamps changes when frames arrive, not the decisions."""
    a, b = pair
    n = 12  # 0.12 s of frames at 100 Hz
    feeds = [
        ReplayFeed(c.frames, c.timestamps, pace=True, max_frames=n) for c in (a, b)
    ]
    streams = _hand([a, b], list(feeds), ["a", "b"])
    run_streams(streams, mode)
    for case, s in zip((a, b), streams, strict=True):
        assert s.result is not None
        np.testing.assert_allclose(
            _alone_scores(case)[: n - 3], s.result.score, rtol=1e-6
        )


def test_a_paced_frame_is_not_handed_over_before_it_is_due(
    pair: tuple[LinearCase, LinearCase],
) -> None:
    """poll returns nothing before the first frame's due time and names that time."""
    a, _ = pair
    feed = ReplayFeed(a.frames, a.timestamps, pace=True)
    start = time.perf_counter_ns() + 3600 * 10**9
    feed.start(start)
    assert (None, start) == (feed.poll(0), feed.next_due_ns())


def _junk_and_clean(clean: UdpSource, junk: UdpSource, case: LinearCase) -> None:
    # The sockets are bound already: datagrams queue until the loop reads them.
    with UdpSender(*clean.address) as tx, UdpSender(*junk.address) as jx:
        for i, (t, values) in enumerate(
            zip(case.timestamps.tolist(), case.frames, strict=True)
        ):
            for _ in range(2):  # datagrams that break the format
                jx.sock.sendto(b"not a frame at all", jx.address)
            # and well-formed frames full of NaN: flagged, never scored
            jx.send(i, t, np.full_like(values, np.nan))
            tx.send(i, t, values)
            if i % 10 == 9:
                time.sleep(0.001)  # keep the receive queues short


@pytest.mark.parametrize("mode", ["loop", "threads"])
def test_a_junk_stream_does_not_disturb_a_clean_one(
    pair: tuple[LinearCase, LinearCase], mode: str
) -> None:
    """Junk datagrams and NaN frames on one UDP stream leave the other stream's decisions whole."""
    a, b = pair
    shape = (a.frames.shape[1],)
    clean = UdpSource("127.0.0.1", 0, shape, max_frames=200, timeout_s=2.0, wait_s=10.0)
    junk = UdpSource("127.0.0.1", 0, shape, max_frames=200, timeout_s=2.0, wait_s=10.0)
    streams = _hand([a, b], [clean, junk], ["clean", "junk"])
    sender = threading.Thread(target=_junk_and_clean, args=(clean, junk, a))
    sender.start()
    try:
        run_streams(streams, mode)
    finally:
        sender.join()
    r_clean, r_junk = (s.result for s in streams)
    assert r_clean is not None
    assert r_junk is not None
    np.testing.assert_allclose(_alone_scores(a), r_clean.score, rtol=1e-6)
    assert (0, 0) == (r_clean.skipped_windows, len(r_clean.bad_reason))
    assert (400, 200, 0) == (junk.n_rejected, len(r_junk.bad_reason), len(r_junk.score))


class _Broken:
    """An on_decision sink that fails on its 10th decision (a controller link gone)."""

    def __init__(self) -> None:
        self.n = 0

    def __call__(self, *record: object) -> None:
        self.n += 1
        if self.n == 10:
            raise OSError("link down")


@pytest.mark.parametrize("mode", ["loop", "threads"])
def test_a_failing_stream_ends_alone(
    pair: tuple[LinearCase, LinearCase], mode: str
) -> None:
    """A stream whose sink fails stops with its reason; the other runs to its end."""
    a, b = pair
    streams = _hand(
        [a, b],
        [ReplayFeed(a.frames, a.timestamps), ReplayFeed(b.frames, b.timestamps)],
        ["ok", "broken"],
    )
    streams[1].loop.on_decision = _Broken()
    run_streams(streams, mode)
    ok, broken = streams
    assert ok.result is not None
    assert broken.result is not None
    assert (None, 197) == (ok.error, len(ok.result.score))
    assert ("link down", 10) == (broken.error, len(broken.result.score))


def test_decision_datagrams_carry_the_stream_index(
    pair: tuple[LinearCase, LinearCase],
) -> None:
    """--send in a hand tags every datagram with its stream's index, in --stream order."""
    a, b = pair
    with DecisionReceiver(port=0, timeout_s=2.0, max_records=94) as rx:
        status = run(
            [
                "--stream",
                f"a={a.path}",
                "--stream",
                f"b={b.path}",
                "--frames",
                "50",
                "--send",
                f"127.0.0.1:{rx.port}",
            ]
        )
        got = list(rx)
    by_stream = {0: 0, 1: 0}
    for d in got:
        by_stream[d.stream] += 1
    assert (0, {0: 47, 1: 47}) == (status, by_stream)


def test_jsonl_lines_name_their_stream(
    pair: tuple[LinearCase, LinearCase], capsys: pytest.CaptureFixture[str]
) -> None:
    """--jsonl in a hand writes each decision with its stream's name."""
    a, b = pair
    run(
        [
            "--stream",
            f"a={a.path}",
            "--stream",
            f"b={b.path}",
            "--frames",
            "5",
            "--jsonl",
        ]
    )
    lines = [
        json.loads(x) for x in capsys.readouterr().out.splitlines() if x.startswith("{")
    ]
    assert ["a", "a", "b", "b"] == sorted(x["stream"] for x in lines)


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["BUNDLE_PLACEHOLDER"], "--stream: give either a BUNDLE or --stream"),
        (["--replay", "x.npz"], "--replay: is for a single BUNDLE"),
        (["--udp", "127.0.0.1:0"], "--udp: is for a single BUNDLE"),
    ],
)
def test_hand_option_misuse_is_a_one_line_error(
    pair: tuple[LinearCase, LinearCase],
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    fragment: str,
) -> None:
    """Mixing --stream with the single-bundle form exits 2 with one line naming the option."""
    a, _ = pair
    extra = [str(a.path) if x == "BUNDLE_PLACEHOLDER" else x for x in extra]
    with pytest.raises(SystemExit) as info:
        main(["--stream", f"a={a.path}", *extra])
    err = capsys.readouterr().err
    assert (2, 1) == (info.value.code, len(err.strip().splitlines()))
    assert fragment in err


def test_a_bad_bundle_in_a_hand_names_its_stream(
    tmp_path: Path,
    pair: tuple[LinearCase, LinearCase],
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A stream whose bundle folder is missing is a one-line error naming that stream."""
    a, _ = pair
    with pytest.raises(SystemExit) as info:
        main(["--stream", f"a={a.path}", "--stream", f"ring={tmp_path / 'nope'}"])
    err = capsys.readouterr().err.strip()
    assert 2 == info.value.code
    assert err.startswith("slipkit-run: error: --stream: ring: ")


def test_pace_on_a_live_input_is_refused(
    pair: tuple[LinearCase, LinearCase], capsys: pytest.CaptureFixture[str]
) -> None:
    """--pace with a single bundle on --udp is a one-line error naming --pace."""
    a, _ = pair
    with pytest.raises(SystemExit) as info:
        main([str(a.path), "--udp", "127.0.0.1:0", "--pace"])
    assert 2 == info.value.code
    assert (
        "slipkit-run: error: --pace: paces replayed frames; --udp frames come at the "
        "sender's pace\n"
    ) == capsys.readouterr().err


def _paced_run(
    pair: tuple[LinearCase, LinearCase], mode: str, n: int, **kw: object
) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Both cases paced through run_streams; per stream (frames, timestamps, scores)."""
    busy = bool(kw.get("busy_poll", False)) if mode == "threads" else False
    spin_ns = int(float(kw.get("spin_us", 0.0)) * 1000) if mode == "threads" else 0
    feeds = [
        ReplayFeed(
            c.frames,
            c.timestamps,
            pace=True,
            max_frames=n,
            busy_poll=busy,
            spin_ns=spin_ns,
        )
        for c in pair
    ]
    streams = _hand(list(pair), list(feeds), ["a", "b"])
    run_streams(streams, mode, **({} if mode == "threads" else kw))  # type: ignore[arg-type]
    out = []
    for s in streams:
        assert s.result is not None
        out.append((s.result.n_frames, s.result.timestamp, s.result.score))
    return out


@pytest.mark.parametrize(
    ("mode", "kw"),
    [
        ("loop", {"busy_poll": True}),
        ("loop", {"spin_us": 5000.0}),
        ("threads", {"busy_poll": True}),
        ("threads", {"spin_us": 5000.0}),
    ],
)
def test_busy_polled_replays_decide_as_sleeping_ones(
    pair: tuple[LinearCase, LinearCase], mode: str, kw: dict[str, object]
) -> None:
    """Spinning to each paced frame (busy poll, or a spin after a short sleep) hands over
    every frame in order and gives the sleeping run's decisions."""
    n = 15  # 0.15 s of frames at 100 Hz
    sleeping = _paced_run(pair, mode, n)
    spinning = _paced_run(pair, mode, n, **kw)
    for (n0, t0, s0), (n1, t1, s1) in zip(sleeping, spinning, strict=True):
        assert (n, n) == (n0, n1)
        assert t0.tolist() == t1.tolist()
        assert sorted(t1.tolist()) == t1.tolist()
        np.testing.assert_array_equal(s0, s1)


def test_busy_poll_wait_ends_a_hand(
    pair: tuple[LinearCase, LinearCase], capsys: pytest.CaptureFixture[str]
) -> None:
    """A busy-polling hand with a silent UDP stream still ends on --wait (exit 1, named)."""
    a, b = pair
    status = run(
        [
            "--stream",
            f"quiet={a.path}@udp:127.0.0.1:0",
            "--stream",
            f"b={b.path}",
            "--pace",
            "--frames",
            "10",
            "--busy-poll",
            "--wait",
            "0.2",
        ]
    )
    out = capsys.readouterr().out
    assert 1 == status
    assert "quiet: no frame arrived within --wait 0.2 s" in out
    assert "busy polling" in out


def test_busy_poll_timeout_ends_a_hand(pair: tuple[LinearCase, LinearCase]) -> None:
    """A busy-polling loop ends on timeout_s once its UDP sender goes quiet, every frame taken."""
    a, b = pair
    shape = (a.frames.shape[1],)
    src = UdpSource("127.0.0.1", 0, shape, timeout_s=0.3, wait_s=5.0)
    replay = ReplayFeed(b.frames, b.timestamps, pace=True, max_frames=10)
    streams = _hand([a, b], [src, replay], ["u", "r"])
    with UdpSender(*src.address) as tx:
        tx.send_all(a.frames[:20], a.timestamps[:20])
        run_streams(streams, "loop", busy_poll=True)
    u, r = (s.result for s in streams)
    assert u is not None
    assert r is not None
    assert (20, True, 10) == (u.n_frames, src.timed_out, r.n_frames)


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--pace", "--spin-us", "-1"], "--spin-us: must be in [0, 100000] us"),
        (["--pace", "--spin-us", "nan"], "--spin-us: must be in [0, 100000] us"),
        (["--spin-us", "50"], "--spin-us: spins before paced replay frames"),
        (
            ["--busy-poll", "--hand-mode", "threads"],
            "--busy-poll: with --hand-mode threads",
        ),
    ],
)
def test_busy_poll_option_errors_are_one_line(
    pair: tuple[LinearCase, LinearCase],
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    fragment: str,
) -> None:
    """A bad --spin-us or --busy-poll combination exits 2 with one line naming the option."""
    a, _ = pair
    with pytest.raises(SystemExit) as info:
        main(["--stream", f"a={a.path}", *extra])
    err = capsys.readouterr().err
    assert (2, 1) == (info.value.code, len(err.strip().splitlines()))
    assert fragment in err


def test_busy_poll_notes_name_what_defeats_it() -> None:
    """--busy-poll under fifo and without --cpus gets one note line each; with --cpus at
    normal priority none."""
    args = argparse.Namespace(busy_poll=True)
    bad = _busy_poll_notes(args, RealtimeOptions(priority="fifo"))
    good = _busy_poll_notes(args, RealtimeOptions(cpus=(0,)))
    assert (2, 0) == (len(bad), len(good))
    assert "RT throttling" in bad[0]
