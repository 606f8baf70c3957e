"""The latency rule (slipkit.runtime.budget) and slipkit-run --check's pacing."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from tests.runtime.helpers import LinearCase

from slipkit.runtime.budget import (
    PACED_MIN_FRAMES,
    UNPACED_NOTE,
    block_p99,
    judge_latency,
    judge_p99,
    paced_frames,
    pool,
)
from slipkit.runtime.cli import run


@pytest.fixture(scope="module")
def generous(tmp_path_factory: pytest.TempPathFactory) -> LinearCase:
    """A bundle whose p99 budget is the whole 10 s frame period (200 frames at 100 Hz)."""
    return LinearCase(
        tmp_path_factory.mktemp("budget"), budget=(10_000.0, 10_000.0), name="generous"
    )


@pytest.mark.parametrize(
    ("p99", "status", "passed"),
    [
        (40.0, "within", True),
        (40.5, "borderline", True),
        (50.0, "borderline", True),
        (62.5, "borderline", True),
        (62.6, "over", False),
    ],
)
def test_margin_bands(p99: float, status: str, passed: bool) -> None:
    """Against 50 us: within up to 0.8 x, borderline (passes) up to 1.25 x, over beyond."""
    judged = judge_p99(p99, 50.0)
    assert (status, passed) == (judged.status, judged.passed)


def test_nothing_measured_fails() -> None:
    """No latency is "not measured" and does not pass."""
    judged = judge_latency([], 50.0)
    assert ("not measured", False) == (judged.status, judged.passed)


def test_one_stalled_block_does_not_decide() -> None:
    """A burst of stalls inside one of the five blocks leaves the judged p99 at the others'."""
    lat = np.full(1000, 10.0)
    lat[100:150] = 5000.0  # all in the first block
    assert (10.0, "within") == (block_p99(lat), judge_latency(lat, 50.0).status)


def test_pool_keeps_each_series_spread_over_the_run() -> None:
    """Decision and prepare frames pooled: every fifth of the pooled run holds a fifth of each."""
    decisions = np.arange(100, dtype=float)  # 0..99
    prepare = 1000.0 + np.arange(50)  # 1000..1049
    pooled = pool(decisions, prepare)
    blocks = np.array_split(pooled, 5)
    assert [20] * 5 == [int(np.sum(b < 1000)) for b in blocks]
    assert [10] * 5 == [int(np.sum(b >= 1000)) for b in blocks]


def test_paced_replay_cap() -> None:
    """A paced replay plays about 3 s of frames, never fewer than 300, never more than there are."""
    assert (6000, PACED_MIN_FRAMES, 200, 360) == (
        paced_frames(10_000, 2000.0),
        paced_frames(10_000, 10.0),
        paced_frames(200, 2000.0),
        paced_frames(10_000, 120.0),
    )


def test_check_paces_by_default_and_says_so(
    generous: LinearCase, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--check replays at the frames' timestamps; --json holds the rule's judgement."""
    out = tmp_path / "s.json"
    assert 0 == run([str(generous.path), "--check", "--json", str(out)])
    summary = json.loads(out.read_text())
    check = summary["latency_check"]
    text = capsys.readouterr().out
    assert (True, True, "within", True, 197) == (
        summary["paced"],
        check["paced"],
        check["status"],
        check["passed"],
        check["timed_frames"],  # decisions (no prepare graph)
    )
    assert "paced: 200 frames at their timestamps (100 Hz)" in text
    assert "check: passed (within)" in text


def test_unpaced_check_says_it_is_unpaced(
    generous: LinearCase, capsys: pytest.CaptureFixture[str]
) -> None:
    """--check --no-pace runs back to back and its verdict line says it understates."""
    assert 0 == run([str(generous.path), "--check", "--no-pace"])
    lines = capsys.readouterr().out.splitlines()
    assert UNPACED_NOTE in lines
    assert f"check: passed (within; {UNPACED_NOTE})" == lines[-1]


def test_pace_without_check(
    generous: LinearCase, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A single bundle takes --pace without --check; without either it is unpaced."""
    out = tmp_path / "s.json"
    assert 0 == run(
        [str(generous.path), "--pace", "--frames", "20", "--json", str(out)]
    )
    assert True is json.loads(out.read_text())["paced"]
    assert 0 == run([str(generous.path), "--json", str(out)])
    assert False is json.loads(out.read_text())["paced"]
    assert UNPACED_NOTE in capsys.readouterr().out


def test_pace_with_choose_session_is_refused(generous: LinearCase) -> None:
    """--pace with --choose-session is one line naming --pace, exit 2."""
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "slipkit.runtime.cli",
            str(generous.path),
            "--choose-session",
            "--pace",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert (
        2,
        "slipkit-run: error: --pace: --choose-session measures the options back to back\n",
    ) == (proc.returncode, proc.stderr)


def test_a_fast_sensor_is_paced_by_spinning() -> None:
    """Frame periods under SPIN_BELOW_MS (2 kHz FSR) spin to each due time; 100 Hz sleeps."""
    from slipkit.runtime.budget import pacing_spins

    assert (True, False, False) == (
        pacing_spins(2000.0),
        pacing_spins(100.0),
        pacing_spins(float("nan")),
    )


def test_check_says_it_spins_for_a_fast_sensor(
    generous: LinearCase,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """With the spin limit above the case's 10 ms period, --check paces by spinning and says so."""
    from slipkit.runtime import budget

    monkeypatch.setattr(budget, "SPIN_BELOW_MS", 20.0)
    assert 0 == run([str(generous.path), "--check"])
    assert "(100 Hz, spinning to each)" in capsys.readouterr().out
