"""Lab Streaming Layer: the inlet source and the decision outlet, over a stand-in pylsl and the real one.

The stand-in (``FakePylsl``) follows pylsl's documented API (``resolve_byprop``,
``StreamInfo``, ``StreamInlet``, ``StreamOutlet``) and runs everywhere; the tests marked
``real`` use an actual outlet -> inlet pair on this machine and are skipped, with the
reason, when pylsl (``pip install 'slipkit[lsl]'``) is missing or its liblsl does not load.
"""

from __future__ import annotations

import json
import os
import queue
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.runtime.helpers import LinearCase

from slipkit.runtime import load_bundle
from slipkit.runtime.cli import main, run
from slipkit.runtime.errors import FrameError
from slipkit.runtime.hand import HandStream, ReplayFeed, StreamBinding, run_streams
from slipkit.runtime.loop import StreamLoop
from slipkit.runtime.lsl import DECISION_CHANNELS, LslOutlet, LslSource
from slipkit.runtime.sources import ReplaySource


class _Xml:
    def __init__(self, name: str = "desc") -> None:
        self.name, self.children, self.value = name, [], None

    def append_child(self, name: str) -> _Xml:
        c = _Xml(name)
        self.children.append(c)
        return c

    def append_child_value(self, name: str, value: str) -> _Xml:
        self.append_child(name).value = value
        return self  # pylsl returns the element itself

    def labels(self) -> list[str]:
        chans = next(c for c in self.children if c.name == "channels")
        return [ch.children[0].value for ch in chans.children]


class FakePylsl:
    """pylsl's documented surface, in memory: one registry of named outlets."""

    cf_float32, cf_double64, cf_string = 1, 2, 3
    proc_clocksync = 1
    IRREGULAR_RATE = 0.0

    def __init__(self) -> None:
        self.outlets: dict[str, FakePylsl.StreamOutlet] = {}
        fake = self

        class StreamInfo:
            def __init__(
                self,
                name: str,
                type: str = "",
                channel_count: int = 1,
                nominal_srate: float = 0.0,
                channel_format: int = 1,
                source_id: str = "",
            ) -> None:
                self._name, self._n, self._fmt = name, channel_count, channel_format
                self._desc = _Xml()

            def name(self) -> str:
                return self._name

            def channel_count(self) -> int:
                return self._n

            def channel_format(self) -> int:
                return self._fmt

            def desc(self) -> _Xml:
                return self._desc

        class StreamOutlet:
            def __init__(self, info: StreamInfo) -> None:
                self.info, self.pushed, self.inlets = info, [], []
                fake.outlets[info.name()] = self

            def push_sample(self, x: list[float], timestamp: float = 0.0) -> None:
                self.pushed.append((list(x), timestamp))
                for q in self.inlets:
                    q.put((list(x), timestamp))

        class StreamInlet:
            def __init__(self, info: StreamInfo, **kwargs: Any) -> None:
                self.q: queue.Queue[Any] = queue.Queue()
                fake.outlets[info.name()].inlets.append(self.q)

            def open_stream(self, timeout: float) -> None:
                pass

            def close_stream(self) -> None:
                pass

            def pull_sample(self, timeout: float = 32e6) -> tuple[Any, Any]:
                try:
                    return (
                        self.q.get(timeout=timeout) if timeout else self.q.get_nowait()
                    )
                except queue.Empty:
                    return None, None

        self.StreamInfo, self.StreamOutlet, self.StreamInlet = (
            StreamInfo,
            StreamOutlet,
            StreamInlet,
        )

    def resolve_byprop(
        self, prop: str, value: str, minimum: int = 1, timeout: float = 0.0
    ) -> list[Any]:
        out = self.outlets.get(value)
        return [] if out is None else [out.info]


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> LinearCase:
    """A linear bundle with its replay (197 decisions over 200 frames)."""
    return LinearCase(tmp_path_factory.mktemp("lsl"), budget=(10_000.0, 10_000.0))


def _alone(case: LinearCase) -> np.ndarray:
    return (
        StreamLoop(load_bundle(case.path))
        .run(ReplaySource(case.frames, case.timestamps))
        .score
    )


def _fake_sensor(fake: FakePylsl, name: str, case: LinearCase, n: int) -> Any:
    """An outlet whose first n frames are already queued for the next inlet."""
    outlet = fake.StreamOutlet(fake.StreamInfo(name, "Tactile", case.frames.shape[1]))
    frames, ts = case.frames[:n], case.timestamps[:n]
    real_inlet = fake.StreamInlet

    def inlet(info: Any, **kw: Any) -> Any:
        made = real_inlet(info, **kw)
        for values, t in zip(frames.tolist(), ts.tolist(), strict=True):
            made.q.put((values, t))
        return made

    fake.StreamInlet = inlet
    return outlet


def test_lsl_source_decides_as_the_replay(case: LinearCase) -> None:
    """Frames pulled from an LSL inlet give the replay's scores."""
    fake = FakePylsl()
    _fake_sensor(fake, "tactile", case, 200)
    src = LslSource("tactile", (3,), max_frames=200, wait_s=1.0, pylsl=fake)
    result = StreamLoop(load_bundle(case.path)).run(src)
    np.testing.assert_allclose(_alone(case), result.score, rtol=1e-6)
    assert (200, False) == (src.n_received, src.timed_out)


def test_lsl_source_refuses_a_stream_of_the_wrong_width(case: LinearCase) -> None:
    """A stream whose channel count is not the frame's size is a FrameError naming the stream."""
    fake = FakePylsl()
    fake.StreamOutlet(fake.StreamInfo("wide", "Tactile", 5))
    src = LslSource("wide", (3,), wait_s=1.0, pylsl=fake)
    with pytest.raises(FrameError, match="lsl wide: the stream has 5 channels"):
        src.open()


def test_lsl_source_that_finds_nothing_waits_out() -> None:
    """No stream of that name within wait_s ends the source as waited out, with no frame."""
    src = LslSource("absent", (3,), wait_s=0.01, pylsl=FakePylsl())
    assert ([], True) == (list(src), src.waited_out)


def test_missing_pylsl_is_a_one_line_install_hint(
    case: LinearCase,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """slipkit-run --lsl without pylsl exits 2 with one line saying what to install."""
    monkeypatch.setitem(sys.modules, "pylsl", None)  # import pylsl -> ImportError
    with pytest.raises(SystemExit) as info:
        main([str(case.path), "--lsl", "tactile"])
    err = capsys.readouterr().err.strip()
    assert 2 == info.value.code
    assert (
        "slipkit-run: error: --lsl: needs pylsl, which is not installed: "
        "pip install 'slipkit[lsl]' (pylsl>=1.16)"
    ) == err


def test_cli_lsl_in_and_out_over_the_stand_in(
    case: LinearCase, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """slipkit-run --lsl IN --lsl-out OUT decides every frame and pushes every decision."""
    fake = FakePylsl()
    _fake_sensor(fake, "tactile", case, 50)
    monkeypatch.setitem(sys.modules, "pylsl", fake)
    out = tmp_path / "s.json"
    status = run(
        [
            str(case.path),
            "--lsl",
            "tactile",
            "--lsl-out",
            "slips",
            "--frames",
            "50",
            "--json",
            str(out),
        ]
    )
    summary = json.loads(out.read_text())
    pushed = fake.outlets["slips"].pushed
    assert (0, 47, 47, 50) == (
        status,
        summary["decisions"],
        len(pushed),
        summary["lsl"]["received"],
    )
    assert list(DECISION_CHANNELS) == fake.outlets["slips"].info.desc().labels()


def test_cli_lsl_that_never_comes_fails_the_run(
    case: LinearCase,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """--lsl with no such stream within --wait exits 1 and says so."""
    monkeypatch.setitem(sys.modules, "pylsl", FakePylsl())
    status = run([str(case.path), "--lsl", "nobody", "--wait", "0.01"])
    assert 1 == status
    assert "lsl: no frame arrived within --wait 0.01 s" in capsys.readouterr().out


def test_outlet_sample_carries_the_decision(case: LinearCase) -> None:
    """Each decision becomes one 8-channel sample: stream, frame, t, score, class, slip, declared, latency."""
    fake = FakePylsl()
    outlet = LslOutlet("slips", ["a", "b"], pylsl=fake)
    loop = StreamLoop(load_bundle(case.path), on_decision=outlet.hook(1))
    r = loop.run(ReplaySource(case.frames[:10], case.timestamps[:10]))
    samples = np.array([x for x, _ in fake.outlets["slips"].pushed])
    expected = np.column_stack(
        [
            np.ones(len(r.frame)),
            r.frame,
            r.timestamp,
            r.score,
            r.klass,
            r.slip,
            r.declared,
            r.latency_ns,
        ]
    )
    np.testing.assert_array_equal(expected, samples)
    assert 7 == outlet.n_pushed


def test_a_hand_stream_can_read_lsl(case: LinearCase) -> None:
    """An LSL stream beside a replay stream in one loop decides as its replay."""
    fake = FakePylsl()
    _fake_sensor(fake, "tactile", case, 200)
    bundle = load_bundle(case.path)
    src = LslSource("tactile", (3,), max_frames=200, wait_s=1.0, pylsl=fake)
    other = load_bundle(case.path)
    streams = [
        HandStream(0, StreamBinding("lsl", case.path), bundle, StreamLoop(bundle), src),
        HandStream(
            1,
            StreamBinding("replay", case.path),
            other,
            StreamLoop(other),
            ReplayFeed(case.frames, case.timestamps),
        ),
    ]
    run_streams(streams, "loop")
    assert streams[0].result is not None
    np.testing.assert_allclose(_alone(case), streams[0].result.score, rtol=1e-6)


# -- the real pylsl -------------------------------------------------------------------
def _real_pylsl() -> Any:
    try:
        import pylsl
    except ImportError:
        pytest.skip("pylsl is not installed (pip install 'slipkit[lsl]')")
    except (RuntimeError, OSError) as exc:
        pytest.skip(f"pylsl is installed but its liblsl does not load: {exc}")
    return pylsl


def _resolves(pylsl: Any, name: str) -> None:
    """Skip (with the reason) when this machine's network cannot discover a local outlet."""
    if not pylsl.resolve_byprop("name", name, 1, 5.0):
        pytest.skip(
            "LSL discovery found no local outlet within 5 s (no multicast on this "
            "machine's interfaces?)"
        )


def _unique(tmp_path: Path, what: str) -> str:
    # Other test runs on this machine may publish LSL streams at the same time.
    return f"slipkit-test-{what}-{os.getpid()}-{tmp_path.name}"


def test_real_lsl_outlet_to_slipkit_run(case: LinearCase, tmp_path: Path) -> None:
    """A real LSL outlet's frames, read by slipkit-run --lsl, give the replay's scores."""
    pylsl = _real_pylsl()
    name = _unique(tmp_path, "in")
    info = pylsl.StreamInfo(name, "Tactile", 3, 100.0, pylsl.cf_float32, name)
    outlet = pylsl.StreamOutlet(info)
    _resolves(pylsl, name)

    def send() -> None:
        if not outlet.wait_for_consumers(10.0):
            return
        for values, t in zip(
            case.frames.tolist(), case.timestamps.tolist(), strict=True
        ):
            outlet.push_sample(values, 1000.0 + t)  # 0.0 would mean "stamp it now"

    sender = threading.Thread(target=send)
    sender.start()
    out = tmp_path / "s.json"
    try:
        status = run(
            [
                str(case.path),
                "--lsl",
                name,
                "--frames",
                "200",
                "--wait",
                "10",
                "--json",
                str(out),
            ]
        )
    finally:
        sender.join()
    summary = json.loads(out.read_text())
    assert (0, 200, 197, 0) == (
        status,
        summary["lsl"]["received"],
        summary["decisions"],
        summary["bad_frames"],
    )


def test_real_lsl_decision_outlet_reaches_an_inlet(
    case: LinearCase, tmp_path: Path
) -> None:
    """Decisions pushed to a real LSL outlet arrive at an inlet, one sample each, in order."""
    pylsl = _real_pylsl()
    name = _unique(tmp_path, "out")
    outlet = LslOutlet(name, ["a"])
    _resolves(pylsl, name)
    found = pylsl.resolve_byprop("name", name, 1, 10.0)
    inlet = pylsl.StreamInlet(found[0])
    inlet.open_stream(10.0)
    deadline = time.monotonic() + 10.0
    while not outlet._outlet.have_consumers() and time.monotonic() < deadline:
        time.sleep(0.01)
    loop = StreamLoop(load_bundle(case.path), on_decision=outlet.hook(0))
    r = loop.run(ReplaySource(case.frames[:20], case.timestamps[:20]))
    got = []
    while len(got) < len(r.frame):
        sample, _ts = inlet.pull_sample(timeout=10.0)
        if sample is None:
            break
        got.append(sample)
    inlet.close_stream()
    assert r.frame.tolist() == [int(s[1]) for s in got]
    np.testing.assert_allclose(r.score, [s[3] for s in got])


def test_a_hands_decision_outlet_tags_each_stream(
    case: LinearCase, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """slipkit-run --stream ... --lsl-out pushes each stream's decisions with its index."""
    fake = FakePylsl()
    monkeypatch.setitem(sys.modules, "pylsl", fake)
    status = run(
        [
            "--stream",
            f"a={case.path}",
            "--stream",
            f"b={case.path}",
            "--frames",
            "20",
            "--lsl-out",
            "hand",
        ]
    )
    index = [int(x[0]) for x, _ in fake.outlets["hand"].pushed]
    assert (0, 17, 17) == (status, index.count(0), index.count(1))
