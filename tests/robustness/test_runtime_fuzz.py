"""The runtime loop under a fuzzed stream: bad frames are flagged and counted, never scored.

The bundle is exact on purpose: integer frames, a dyadic mean and scale, weights in
quarters and a threshold between two reachable scores, so float32 and float64 give
the same decisions and the reference below can demand equality.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tests.runtime.helpers import RATE_HZ, linear_graph, manifest, pin_bundle

from slipkit.runtime import (
    StreamLoop,
    UdpSender,
    UdpSource,
    load_bundle,
    write_bundle,
)
from slipkit.runtime.loop import BAD_REASONS
from slipkit.runtime.sources import Frame

N_CH = 3
WINDOW = 4
MEAN, SCALE = 0.5, 2.0
THRESHOLD = 0.3  # scores are multiples of 1/16: never within 0.0125 of it
PERIOD = 1.0 / RATE_HZ
MAX_GAP = 1.5 * PERIOD

#: Fault kinds the fuzzer injects; "valid" frames and timing are the rest.
KINDS = (
    "valid",
    "valid_list",
    "nan",
    "inf",
    "huge",
    "short",
    "long",
    "ragged",
    "text",
    "complex",
    "bool",
    "object",
    "ts_nan",
    "ts_inf",
    "ts_text",
    "duplicate",
    "out_of_order",
    "gap",
)

_WEIGHTS = np.arange(WINDOW * N_CH) % 7 / 4 - 0.75


def _bundle(root: Path, *, hop: int = 1, k: int = 2) -> Path:
    man = manifest(
        WINDOW * N_CH,
        threshold=THRESHOLD,
        window=WINDOW,
        hop=hop,
        k=k,
        preprocessing=[
            {"op": "standardize", "mean": [MEAN] * N_CH, "scale": [SCALE] * N_CH}
        ],
    )
    man["name"] = f"fuzz_h{hop}_k{k}"
    return write_bundle(root / man["name"], linear_graph(_WEIGHTS, 0.0), man)


@dataclass
class Stream:
    """A fuzzed stream: what is fed, and what an independent reference expects."""

    values: list[Any] = field(default_factory=list)
    times: list[Any] = field(default_factory=list)
    kinds: list[str] = field(default_factory=list)


def make_stream(kinds: list[str], seed: int) -> Stream:
    """Frames of the given kinds: a jittered 100 Hz clock, integer values in [-8, 8]."""
    rng = np.random.default_rng(seed)
    out = Stream()
    clock = 0.0
    last_fed = math.nan
    for kind in kinds:
        # Jitter below a third of a period keeps the clean clock increasing and in step.
        clock += PERIOD * (1.0 + rng.uniform(-0.3, 0.3))
        good = rng.integers(-8, 9, size=N_CH).astype(np.float64)
        values: Any = good
        ts: Any = clock
        if kind == "valid_list":
            values = good.tolist()
        elif kind == "nan":
            values = good.copy()
            values[rng.integers(N_CH)] = np.nan
        elif kind == "inf":
            values = good.copy()
            values[rng.integers(N_CH)] = rng.choice([np.inf, -np.inf])
        elif kind == "huge":  # finite, but beyond float32 once in the graph
            values = good.copy()
            values[rng.integers(N_CH)] = 1e300
        elif kind == "short":
            values = good[:2]
        elif kind == "long":
            values = np.append(good, 1.0).reshape(2, 2)
        elif kind == "ragged":
            values = [[1.0], [2.0, 3.0], 4.0]
        elif kind == "text":
            values = np.array(["1", "2", "3"])
        elif kind == "complex":
            values = good.astype(np.complex128)
        elif kind == "bool":
            values = good > 0
        elif kind == "object":
            values = np.array([1.0, None, 2.0], dtype=object)
        elif kind == "ts_nan":
            ts = math.nan
        elif kind == "ts_inf":
            ts = math.inf
        elif kind == "ts_text":
            ts = "0.01"
        elif kind == "duplicate" and not math.isnan(last_fed):
            ts = last_fed
        elif kind == "out_of_order" and not math.isnan(last_fed):
            ts = last_fed - 0.5 * PERIOD
        elif kind == "gap":  # 1 to 5 dropped frames
            clock += PERIOD * int(rng.integers(1, 6))
            ts = clock
        if isinstance(ts, float) and math.isfinite(ts):
            last_fed = ts
        out.values.append(values)
        out.times.append(ts)
        out.kinds.append(kind)
    return out


def reference(
    stream: Stream, *, hop: int = 1, k: int = 2, skip_gaps: bool = False
) -> dict[str, Any]:
    """What the loop must report, computed frame by frame from the kinds and times."""
    value_reason = {
        "nan": "nonfinite",
        "inf": "nonfinite",
        "short": "shape",
        "long": "shape",
        "ragged": "shape",
        "text": "dtype",
        "complex": "dtype",
        "bool": "dtype",
        "object": "dtype",
    }
    n = len(stream.kinds)
    reasons: list[str | None] = []
    gap_before = np.zeros(n, dtype=bool)
    prev = math.nan
    for i, (kind, ts) in enumerate(zip(stream.kinds, stream.times, strict=True)):
        reason = value_reason.get(kind)
        if not (isinstance(ts, float) and math.isfinite(ts)):
            reason = reason or "timestamp"
        else:
            dt = ts - prev
            if dt == 0:
                reason = reason or "duplicate_time"
            elif dt < 0:
                reason = reason or "time_order"
            elif dt > MAX_GAP:
                gap_before[i] = True
            prev = ts
        reasons.append(reason)
    bad = np.array([r is not None for r in reasons])
    huge = np.array([kind == "huge" for kind in stream.kinds])
    frames = np.array(
        [
            np.zeros(N_CH) if kind in value_reason else v
            for v, kind in zip(stream.values, stream.kinds, strict=True)
        ],
        dtype=np.float64,
    )
    decided, scores, skipped, nonfinite = [], [], 0, 0
    slip, declared = [], []
    run = 0
    for end in range(WINDOW - 1, n, hop):
        lo = end - WINDOW + 1
        if bad[lo : end + 1].any() or (
            skip_gaps and gap_before[lo + 1 : end + 1].any()
        ):
            skipped += 1
            run = 0
            continue
        if huge[lo : end + 1].any():
            skipped += 1
            nonfinite += 1
            run = 0
            continue
        score = float(((frames[lo : end + 1] - MEAN) / SCALE).reshape(-1) @ _WEIGHTS)
        decided.append(end)
        scores.append(score)
        slip.append(score >= THRESHOLD)
        run = run + 1 if slip[-1] else 0
        declared.append(run >= k)
    bad_index = [i for i, r in enumerate(reasons) if r is not None]
    return {
        "bad_frame": bad_index,
        "bad_reason": [reasons[i] for i in bad_index],
        "gaps": int(gap_before.sum()),
        "skipped": skipped,
        "nonfinite": nonfinite,
        "frame": decided,
        "score": scores,
        "slip": slip,
        "declared": declared,
    }


def run_loop(loop: StreamLoop, stream: Stream) -> Any:
    """Feed the stream through ``StreamLoop.run`` as Frame tuples (the sources' path)."""
    loop.reset()
    source = (
        Frame(i, ts, values, 0)
        for i, (values, ts) in enumerate(zip(stream.values, stream.times, strict=True))
    )
    with warnings.catch_warnings():
        # The "huge" frames overflow the float32 cast on purpose.
        warnings.filterwarnings("ignore", "overflow encountered in cast")
        return loop.run(source)


def assert_matches(result: Any, ref: dict[str, Any]) -> None:
    """The loop's flags, counts and decisions equal the reference's."""
    assert ref["bad_frame"] == result.bad_frame.tolist()
    assert ref["bad_reason"] == list(result.bad_reason)
    assert (ref["gaps"], ref["skipped"], ref["nonfinite"]) == (
        result.gaps,
        result.skipped_windows,
        result.nonfinite_windows,
    )
    assert ref["frame"] == result.frame.tolist()
    assert ref["score"] == result.score.tolist()
    assert ref["slip"] == result.slip.tolist()
    assert ref["declared"] == result.declared.tolist()


@pytest.fixture(scope="module")
def bundles(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[int, int], Any]:
    root = tmp_path_factory.mktemp("fuzz")
    return {
        (hop, k): load_bundle(_bundle(root, hop=hop, k=k))
        for hop, k in [(1, 2), (3, 1)]
    }


@pytest.mark.parametrize(("hop", "k", "skip_gaps"), [(1, 2, False), (3, 1, True)])
def test_ten_thousand_fuzzed_frames_are_flagged_counted_and_never_scored(
    bundles: dict[tuple[int, int], Any], hop: int, k: int, skip_gaps: bool
) -> None:
    """12,000 frames with every fault kind: no crash, each bad frame flagged, bad windows skipped, summary counts."""
    rng = np.random.default_rng(8)
    n = 12_000
    faults = rng.choice(KINDS[2:], size=n)
    kinds = np.where(rng.random(n) < 0.8, rng.choice(KINDS[:2], size=n), faults)
    stream = make_stream(kinds.tolist(), seed=hop)
    ref = reference(stream, hop=hop, k=k, skip_gaps=skip_gaps)
    result = run_loop(StreamLoop(bundles[hop, k], skip_gaps=skip_gaps), stream)
    assert_matches(result, ref)
    summary = result.summary()
    expected_counts = dict.fromkeys(BAD_REASONS, 0)
    for r in ref["bad_reason"]:
        expected_counts[r] += 1
    assert expected_counts == summary["bad_by_reason"]
    assert (n, len(ref["bad_frame"]), ref["skipped"], ref["gaps"]) == (
        summary["frames"],
        summary["bad_frames"],
        summary["skipped_windows"],
        summary["gaps"],
    )
    assert len(ref["frame"]) == summary["decisions"]
    # The fuzz really exercised every reason and both skip paths.
    assert all(count > 100 for count in expected_counts.values()), expected_counts
    assert ref["nonfinite"] > 100
    assert ref["gaps"] > 100
    assert len(ref["frame"]) > 1000


@settings(max_examples=60, deadline=None)
@given(
    kinds=st.lists(st.sampled_from(KINDS), min_size=1, max_size=40),
    seed=st.integers(0, 2**16),
    skip_gaps=st.booleans(),
)
def test_any_short_stream_matches_the_reference(
    bundles: dict[tuple[int, int], Any], kinds: list[str], seed: int, skip_gaps: bool
) -> None:
    """Any mix of fault kinds, however short, gives the reference's flags and decisions."""
    stream = make_stream(kinds, seed)
    loop = StreamLoop(bundles[1, 2], skip_gaps=skip_gaps)
    assert_matches(run_loop(loop, stream), reference(stream, skip_gaps=skip_gaps))


def test_gaps_are_counted_and_skipped_only_when_asked(
    bundles: dict[tuple[int, int], Any],
) -> None:
    """Two dropped frames are one gap; its windows are scored by default and skipped with skip_gaps."""
    times = [i * PERIOD for i in range(5)] + [(i + 2) * PERIOD for i in range(5, 12)]
    good = np.ones(N_CH)
    results = []
    for skip in (False, True):
        loop = StreamLoop(bundles[1, 2], skip_gaps=skip)
        for t in times:
            loop.step(good, t)
        results.append(loop.result())
    # Windows of 4 end at frames 3..11; those ending at 5, 6, 7 span the gap before 5.
    assert (1, 0, list(range(3, 12))) == (
        results[0].gaps,
        results[0].skipped_windows,
        results[0].frame.tolist(),
    )
    assert (1, 3, [3, 4, 8, 9, 10, 11]) == (
        results[1].gaps,
        results[1].skipped_windows,
        results[1].frame.tolist(),
    )


def test_step_reports_the_reason_and_keeps_going(
    bundles: dict[tuple[int, int], Any],
) -> None:
    """step() never raises on a bad frame; last_bad names it and the next good frames are scored again."""
    loop = StreamLoop(bundles[1, 2])
    good = np.ones(N_CH)
    out = [loop.step(good, i * PERIOD) for i in range(4)]
    assert [None, None, None, False] == out
    assert loop.step(np.array([np.nan, 1.0, 1.0]), 4 * PERIOD) is None
    assert "nonfinite" == loop.last_bad
    assert loop.step(good, 4 * PERIOD) is None
    assert "duplicate_time" == loop.last_bad
    assert [None, None, None, False] == [
        loop.step(good, (5 + i) * PERIOD) for i in range(4)
    ]
    assert loop.last_bad is None
    assert 2 == loop.n_bad


def test_no_timestamp_skips_only_the_time_checks(
    bundles: dict[tuple[int, int], Any],
) -> None:
    """Without timestamps the values are still checked and decisions recorded with a NaN time."""
    loop = StreamLoop(bundles[1, 2])
    for _ in range(4):
        loop.step(np.ones(N_CH))
    loop.step(np.ones(2))
    result = loop.result()
    assert ([3], ("shape",)) == (result.frame.tolist(), result.bad_reason)
    assert math.isnan(result.timestamp[0])


@pytest.mark.parametrize("bad", [1.0, 0.5, "x", math.nan])
def test_gap_tolerance_must_exceed_one_period(
    bundles: dict[tuple[int, int], Any], bad: Any
) -> None:
    """A gap tolerance of one period or less (which would flag every frame) is refused by name."""
    with pytest.raises(ValueError, match="max_gap_periods"):
        StreamLoop(bundles[1, 2], max_gap_periods=bad)


def test_udp_stream_with_bad_values_is_flagged_by_the_loop(
    bundles: dict[tuple[int, int], Any],
) -> None:
    """Well-formed datagrams carrying NaN reach the loop and are flagged; malformed ones never do."""
    with (
        UdpSource("127.0.0.1", 0, (N_CH,), timeout_s=0.3) as src,
        UdpSender(*src.address) as tx,
    ):
        for i in range(20):
            values = [np.nan, 0.0, 0.0] if i in (7, 8) else [1.0, 2.0, 3.0]
            tx.send(i, i * PERIOD, values)
        tx.send(5, 21 * PERIOD, [1.0, 2.0, 3.0])  # late index: the source rejects it
        result = StreamLoop(bundles[1, 2]).run(src)
    assert ([7, 8], ("nonfinite", "nonfinite")) == (
        result.bad_frame.tolist(),
        result.bad_reason,
    )
    assert (20, 1) == (src.n_received, src.n_rejected)
    # 17 complete windows; the 4 + 1 holding frame 7 or 8 are skipped.
    assert (12, 5) == (len(result.frame), result.skipped_windows)


def test_missing_pins_are_data_but_infinities_are_flagged(tmp_path: Path) -> None:
    """In a pins bundle NaN pins (not detected) pass to the features; an infinite pin is a bad frame."""
    bundle = load_bundle(pin_bundle(tmp_path))
    rng = np.random.default_rng(3)
    pins = np.cumsum(rng.normal(scale=0.1, size=(30, 8)), axis=0)
    pins[5:9, [1, 5]] = np.nan  # pin 1 lost for four frames (x and y)
    pins[20, 2] = np.inf
    times = np.arange(30) / RATE_HZ
    loop = StreamLoop(bundle)
    assert loop.nan_is_missing
    result = loop.run(
        Frame(i, t, v, 0) for i, (v, t) in enumerate(zip(pins, times, strict=True))
    )
    assert ([20], ("nonfinite",)) == (result.bad_frame.tolist(), result.bad_reason)
    # window 2: the windows ending at frames 20 and 21 hold the infinity.
    assert [i for i in range(1, 30) if i not in (20, 21)] == result.frame.tolist()
    assert np.isfinite(result.score).all()
    strict = StreamLoop(bundle, nan_is_missing=False).run(
        Frame(i, t, v, 0) for i, (v, t) in enumerate(zip(pins, times, strict=True))
    )
    assert [5, 6, 7, 8, 20] == strict.bad_frame.tolist()


def test_slipkit_run_reports_the_counts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """slipkit-run prints and writes (JSON) the bad frames by reason, gaps and skipped windows."""
    import json

    from slipkit.runtime.cli import run as cli_run

    bundle = _bundle(tmp_path)
    frames = np.ones((40, N_CH))
    frames[[10, 30], 1] = np.nan
    times = np.arange(40) * PERIOD
    times[20:] += 3 * PERIOD  # three dropped frames before frame 20
    np.savez(tmp_path / "replay.npz", frames=frames, timestamps=times)
    out = tmp_path / "summary.json"
    assert 0 == cli_run(
        [str(bundle), "--replay", str(tmp_path / "replay.npz"), "--json", str(out)]
    )
    printed = capsys.readouterr().out
    assert "flagged: 2 bad frames (nonfinite 2), 1 gaps, 8 windows skipped" in printed
    summary = json.loads(out.read_text())
    assert (2, 2, 1, 8, 29) == (
        summary["bad_frames"],
        summary["bad_by_reason"]["nonfinite"],
        summary["gaps"],
        summary["skipped_windows"],
        summary["decisions"],
    )


@pytest.mark.parametrize("glitch", [1e9, -5.0])
def test_one_glitched_timestamp_flags_one_frame_and_one_gap(
    bundles: dict[tuple[int, int], Any], glitch: float
) -> None:
    """A timestamp far ahead or behind flags a single frame and counts a single gap, then the stream recovers."""
    loop = StreamLoop(bundles[1, 2])
    for i in range(20):
        loop.step(np.ones(N_CH), glitch if i == 10 else i * PERIOD)
    result = loop.result()
    assert (1, ("time_order",), 1) == (
        len(result.bad_frame),
        result.bad_reason,
        result.gaps,
    )
    assert [10 if glitch < 0 else 11] == result.bad_frame.tolist()
    assert 19 == result.frame[-1]
