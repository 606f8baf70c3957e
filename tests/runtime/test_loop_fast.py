"""StreamLoop's hop-1 fast path (_step_hop1) gives step's results, bad frames included."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.runtime.helpers import RATE_HZ, linear_graph, manifest

from slipkit.runtime import StreamLoop, load_bundle, write_bundle
from slipkit.runtime.loop import LoopResult

N_CH = 3
BASELINE = [{"op": "baseline_first", "frames": 3, "hop": 1}]


def _bundle(
    root: Path,
    *,
    window: int = 1,
    hop: int = 1,
    preprocessing: list[dict[str, Any]] | None = None,
    streams: list[str] | None = None,
    argmax: bool = False,
) -> Path:
    pre = BASELINE if preprocessing is None else preprocessing
    n_in = window * N_CH
    if pre and pre[-1]["op"] == "select":
        n_in = window * len(pre[-1]["indices"])
    rng = np.random.default_rng(1)
    if argmax:
        decision = {
            "output": "score",
            "rule": "argmax",
            "classes": ["static", "slip", "roll"],
            "slip_classes": ["slip", "roll"],
            "positive": "slip",
        }
        man = manifest(
            n_in, threshold=None, window=window, hop=hop, k=2, decision=decision
        )
        man["preprocessing"] = pre
        graph = linear_graph(rng.normal(size=(n_in, 3)), [0.0, 0.1, -0.1])
    else:
        man = manifest(
            n_in, threshold=0.0, window=window, hop=hop, k=2, preprocessing=pre
        )
        graph = linear_graph(rng.normal(size=n_in), 0.05)
    if streams is not None:
        man["frame"]["streams"] = streams
    return write_bundle(root / "b", graph, man)


def _faulty_stream() -> tuple[list[Any], list[Any], dict[str, int]]:
    """300 frames at 100 Hz with every kind of fault, and the flags step gives them."""
    rng = np.random.default_rng(0)
    values: list[Any] = list(rng.normal(size=(300, N_CH)))
    times: list[Any] = list(np.arange(300) / RATE_HZ)
    values[1] = np.array([np.nan, 0.0, 0.0])  # during the baseline: never collected
    values[20] = np.array([0.0, np.nan, 0.0])
    values[25] = np.array([np.inf, 0.0, 0.0])
    values[26] = np.array([0.0, 0.0, -np.inf])
    values[30] = np.array([1e39, 0.0, 0.0])  # finite, overflows the float32 input
    values[35] = np.zeros(N_CH - 1)  # shape
    values[40] = [0.5, -0.5, 0.25]  # a list: a good frame through the slow path
    values[45] = np.array(["a", "b", "c"])  # dtype
    values[47] = np.array([1, -2, 3])  # integers: a good frame
    times[50] = float("nan")
    times[60] = times[59]  # duplicate
    times[70] = times[69] - 0.5 / RATE_HZ  # out of order
    for i in range(80, 300):  # two dropped frames: a gap
        times[i] = times[i] + 2 / RATE_HZ
    expected = {
        "dtype": 1,
        "shape": 1,
        "nonfinite": 4,
        "timestamp": 1,
        "duplicate_time": 1,
        "time_order": 1,
    }
    return values, times, expected


def _run(loop: StreamLoop, step: Any, values: list[Any], times: list[Any]) -> Any:
    flags = []
    for v, t in zip(values, times, strict=True):
        step(v, t)
        flags.append(loop.last_bad)
    return loop.result(), flags


def _comparable(result: LoopResult) -> tuple[Any, ...]:
    return (
        result.frame.tolist(),
        result.timestamp.tolist(),
        result.score.tolist(),
        result.slip.tolist(),
        result.declared.tolist(),
        result.klass.tolist(),
        result.n_frames,
        result.bad_frame.tolist(),
        result.bad_reason,
        result.skipped_windows,
        result.nonfinite_windows,
        result.gaps,
    )


@pytest.mark.filterwarnings("ignore:overflow encountered in cast")
@pytest.mark.parametrize(
    ("window", "skip_gaps", "argmax"),
    [
        (1, False, False),
        (1, True, False),
        (1, False, True),
        (4, False, False),
        (4, True, False),
    ],
)
def test_fast_path_equals_step_on_a_faulty_stream(
    tmp_path: Path, window: int, skip_gaps: bool, argmax: bool
) -> None:
    """On a stream with every fault, the fast path's records and flags equal step's, before and after reset."""
    values, times, expected_bad = _faulty_stream()
    path = _bundle(tmp_path, window=window, argmax=argmax)
    # A bundle each: a loaded bundle's ops (the baseline) hold one stream's state.
    fast = StreamLoop(load_bundle(path), skip_gaps=skip_gaps)
    general = StreamLoop(load_bundle(path), skip_gaps=skip_gaps)
    fast_result, fast_flags = _run(fast, fast.step, values, times)
    fast.reset()
    again, _ = _run(fast, fast.step, values, times)

    def step(v: Any, t: Any) -> Any:
        return StreamLoop.step(general, v, t)

    general_result, general_flags = _run(general, step, values, times)
    assert (
        StreamLoop._step_hop1,
        _comparable(general_result),
        general_flags,
        _comparable(general_result),
    ) == (
        fast.step.__func__,  # type: ignore[attr-defined]
        _comparable(fast_result),
        fast_flags,
        _comparable(again),
    )
    # the frame that overflows float32 is in `window` windows
    assert (expected_bad, window) == (
        fast_result.bad_counts(),
        fast_result.nonfinite_windows,
    )


def test_bad_frames_never_reach_the_baseline(tmp_path: Path) -> None:
    """A NaN frame among the baseline frames and one after it leave the baseline the median of the good ones."""
    loop = StreamLoop(load_bundle(_bundle(tmp_path)))
    frames = [
        np.array([1.0, 2.0, 3.0]),
        np.array([np.nan, 0.0, 0.0]),
        np.array([3.0, 4.0, 5.0]),
        np.array([5.0, 0.0, 1.0]),
        np.array([0.0, np.inf, 0.0]),
        np.array([7.0, 7.0, 7.0]),
    ]
    for i, f in enumerate(frames):
        loop.step(f, i / RATE_HZ)
    (op,) = loop._ops
    assert ([3.0, 2.0, 3.0], 2) == (op._base[0].tolist(), loop.n_bad)


@pytest.mark.parametrize(
    ("window", "hop", "preprocessing", "streams", "io_binding", "expected"),
    [
        (1, 1, None, None, True, True),
        (1, 1, [], None, True, True),
        (
            1,
            1,
            [{"op": "standardize", "mean": [0.0] * N_CH, "scale": [2.0] * N_CH}],
            None,
            True,
            True,
        ),
        (2, 1, None, None, True, True),
        (2, 2, None, None, True, False),  # frames between hops are never in an input
        (1, 1, None, None, False, False),  # session.run, no binding
        (1, 1, None, ["pins"], True, False),  # NaN means missing
        (1, 1, [{"op": "select", "indices": [0, 2]}], None, True, False),  # drops
    ],
)
def test_fast_path_only_where_the_input_test_stands_for_the_frame(
    tmp_path: Path,
    window: int,
    hop: int,
    preprocessing: list[dict[str, Any]] | None,
    streams: list[str] | None,
    io_binding: bool,
    expected: bool,
) -> None:
    """The fast path is chosen for hop 1, a binding, values that are never missing and value-keeping ops only."""
    bundle = load_bundle(
        _bundle(
            tmp_path,
            window=window,
            hop=hop,
            preprocessing=preprocessing,
            streams=streams,
        )
    )
    loop = StreamLoop(bundle, io_binding=io_binding)
    assert expected == (getattr(loop.step, "__func__", None) is StreamLoop._step_hop1)


@pytest.mark.parametrize(("window", "hop"), [(1, 1), (3, 2)])
def test_a_gap_starts_a_new_recording_for_a_baseline_bundle(
    tmp_path: Path, window: int, hop: int
) -> None:
    """baseline_first across a gap: the recording after it is scored as a fresh loop
    scores it alone (its own baseline, window and hop grid), on the fast path too."""
    pre = [{"op": "baseline_first", "frames": 3, "hop": hop}]
    path = _bundle(tmp_path, window=window, hop=hop, preprocessing=pre)
    rng = np.random.default_rng(3)
    first, second = rng.normal(size=(11, N_CH)), rng.normal(size=(40, N_CH)) + 5.0
    t1 = np.arange(len(first)) / RATE_HZ
    t2 = t1[-1] + (10 + np.arange(len(second))) / RATE_HZ  # a gap of 10 periods
    loop = StreamLoop(load_bundle(path))
    for row, t in zip([*first, *second], [*t1, *t2], strict=True):
        loop.step(row, float(t))
    both = loop.result()
    alone = StreamLoop(load_bundle(path))
    for row, t in zip(second, t2, strict=True):
        alone.step(row, float(t))
    ref = alone.result()
    after = both.frame >= len(first)
    assert 1 == both.gaps
    assert (ref.frame + len(first)).tolist() == both.frame[after].tolist()
    np.testing.assert_allclose(ref.score, both.score[after], rtol=1e-6)


def test_a_few_dropped_frames_keep_the_baseline_of_the_recording(
    tmp_path: Path,
) -> None:
    """baseline_first across a gap shorter than restart_gap_periods (dropped frames of a
    live stream): the baseline stays the recording's, so the scores after it equal the
    stream's scores without the dropout; a long gap restarts the baseline."""
    pre = [{"op": "baseline_first", "frames": 3, "hop": 1}]
    path = _bundle(tmp_path, window=1, hop=1, preprocessing=pre)
    rng = np.random.default_rng(4)
    rows = rng.normal(size=(40, N_CH)) + np.linspace(0, 5, 40)[:, None]
    t = np.arange(len(rows)) / RATE_HZ
    full = StreamLoop(load_bundle(path))
    for row, ts in zip(rows, t, strict=True):
        full.step(row, float(ts))
    ref = full.result()
    keep = np.ones(len(rows), dtype=bool)
    keep[20:22] = False  # two dropped frames: a gap of 3 periods
    short = StreamLoop(load_bundle(path))
    for row, ts in zip(rows[keep], t[keep], strict=True):
        short.step(row, float(ts))
    res = short.result()
    assert 1 == res.gaps
    np.testing.assert_allclose(ref.score[keep], res.score, rtol=1e-6)
    restart = StreamLoop(load_bundle(path), restart_gap_periods=2.0)
    for row, ts in zip(rows[keep], t[keep], strict=True):
        restart.step(row, float(ts))
    after = restart.result().frame >= 20
    assert not np.allclose(
        ref.score[keep][after], restart.result().score[after], rtol=1e-6
    )


def test_restart_gap_periods_below_max_gap_periods_is_refused(tmp_path: Path) -> None:
    """A restart threshold under the gap threshold is refused, naming the parameter."""
    path = _bundle(tmp_path, window=1, hop=1, preprocessing=BASELINE)
    with pytest.raises(ValueError, match="restart_gap_periods"):
        StreamLoop(load_bundle(path), restart_gap_periods=1.2)
