"""Decisions out: the datagram layout, the UDP and JSON lines sinks, and ``slipkit-run --send / --jsonl``."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from tests.runtime.helpers import LinearCase

from slipkit.runtime.cli import main, run
from slipkit.runtime.errors import FrameError
from slipkit.runtime.sinks import (
    DECISION_SIZE,
    Decision,
    DecisionReceiver,
    UdpSink,
    pack_decision,
    unpack_decision,
)

decisions = st.builds(
    Decision,
    frame=st.integers(0, 2**64 - 1),
    timestamp=st.floats(allow_nan=False),
    score=st.floats(width=32, allow_nan=False),
    klass=st.integers(-(2**15), 2**15 - 1),
    slip=st.booleans(),
    declared=st.booleans(),
    latency_ns=st.integers(0, 2**64 - 1),
    stream=st.integers(0, 255),
)


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> LinearCase:
    """A linear bundle with its replay (197 decisions over 200 frames)."""
    return LinearCase(tmp_path_factory.mktemp("sinks"), budget=(10_000.0, 10_000.0))


@given(decisions)
def test_pack_unpack_round_trip(d: Decision) -> None:
    """Every in-range record survives pack -> unpack unchanged, in 40 bytes."""
    data = pack_decision(d)
    assert (DECISION_SIZE, d) == (len(data), unpack_decision(data))


def test_nan_timestamp_round_trips() -> None:
    """A record without a sensor time carries NaN through the datagram."""
    d = unpack_decision(pack_decision(Decision(3, math.nan, 0.5, -1, True, False, 7)))
    assert (True, 3) == (math.isnan(d.timestamp), d.frame)


def test_unpack_names_a_wrong_magic() -> None:
    """A datagram with another magic is refused naming the magic."""
    data = b"XXXX" + pack_decision(Decision(0, 0.0, 0.0, 0, False, False, 0))[4:]
    with pytest.raises(FrameError, match="magic"):
        unpack_decision(data)


def test_send_to_nobody_is_counted_not_raised() -> None:
    """Sends with no listener never raise: each is either handed to the kernel or counted as an error."""
    with DecisionReceiver(port=0, timeout_s=0.01) as rx:
        port = rx.port  # free a port nobody listens on
    with UdpSink("127.0.0.1", port) as sink:
        for i in range(5):
            sink(i, 0.0, 0.0, 0, False, False, 0)
        assert 5 == sink.n_sent + sink.n_errors


def test_send_delivers_every_decision_in_order(
    case: LinearCase, tmp_path: Path
) -> None:
    """slipkit-run --send delivers every decision, in order, with the summary's scores."""
    out = tmp_path / "s.json"
    with DecisionReceiver(port=0, timeout_s=2.0, max_records=197) as rx:
        status = run(
            [
                str(case.path),
                "--send",
                f"127.0.0.1:{rx.port}",
                "--json",
                str(out),
            ]
        )
        got = list(rx)
    summary = json.loads(out.read_text())
    assert 0 == status
    assert (197, 197, 0) == (
        summary["decisions"],
        summary["send"]["sent"],
        summary["send"]["errors"],
    )
    assert list(range(3, 200)) == [d.frame for d in got]
    np.testing.assert_allclose(case.scores, [d.score for d in got], rtol=1e-5)
    assert summary["slip_decisions"] == sum(d.slip for d in got)
    assert summary["declared"] == sum(d.declared for d in got)
    np.testing.assert_allclose(case.timestamps[3:], [d.timestamp for d in got])


def test_jsonl_prints_one_line_per_decision(
    case: LinearCase, capsys: pytest.CaptureFixture[str]
) -> None:
    """--jsonl prints one parseable JSON object per decision, frame by frame."""
    assert 0 == run([str(case.path), "--jsonl", "--frames", "20"])
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("{")]
    rows = [json.loads(ln) for ln in lines]
    assert list(range(3, 20)) == [r["frame"] for r in rows]
    assert {"frame", "t", "score", "class", "slip", "declared", "latency_ns"} == set(
        rows[0]
    )
    np.testing.assert_allclose(case.scores[:17], [r["score"] for r in rows], rtol=1e-5)


@pytest.mark.parametrize("bad", ["nohost", "127.0.0.1:99999", ":9000", "h:0"])
def test_bad_send_is_a_one_line_error(
    case: LinearCase, bad: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bad --send value stops slipkit-run with status 2 and one line naming --send."""
    with pytest.raises(SystemExit) as info:
        main([str(case.path), "--send", bad])
    err = capsys.readouterr().err
    assert 2 == info.value.code
    assert 1 == len(err.strip().splitlines())
    assert re.match(r"slipkit-run: error: --send: ", err)


def test_send_and_jsonl_together_carry_the_same_decisions(
    case: LinearCase, capsys: pytest.CaptureFixture[str]
) -> None:
    """--send and --jsonl at once hand the same frames and scores to both sinks."""
    with DecisionReceiver(port=0, timeout_s=2.0, max_records=17) as rx:
        status = run(
            [
                str(case.path),
                "--frames",
                "20",
                "--jsonl",
                "--send",
                f"127.0.0.1:{rx.port}",
            ]
        )
        got = [(d.frame, d.score) for d in rx]
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("{")]
    rows = [json.loads(ln) for ln in lines]
    assert 0 == status
    assert [r["frame"] for r in rows] == [f for f, _ in got]
    np.testing.assert_allclose(
        [r["score"] for r in rows], [s for _, s in got], rtol=1e-6
    )


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ("127.0.0.1:70000", "port 70000 is out of range: a port is in [1, 65535]"),
        ("127.0.0.1:0", "port 0 is out of range: a port is in [1, 65535]"),
        ("127.0.0.1:x", "must be HOST:PORT"),
    ],
)
def test_send_says_a_port_is_out_of_range(
    case: LinearCase, bad: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A --send port outside 1-65535 is named as out of range, not as a malformed
    HOST:PORT; a non-number port is."""
    with pytest.raises(SystemExit) as info:
        main([str(case.path), "--send", bad])
    assert 2 == info.value.code
    assert f"slipkit-run: error: --send: {message}" in capsys.readouterr().err
