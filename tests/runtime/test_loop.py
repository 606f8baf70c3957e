"""The streaming loop: ring buffer, preprocessing, decision rule, debounce, latency summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from tests.runtime.helpers import (
    RATE_HZ,
    LinearCase,
    frames,
    linear_graph,
    manifest,
    windows,
)

from slipkit.features.pins import pin_velocities, velocity_features
from slipkit.models.online import debounce
from slipkit.runtime import (
    BundleError,
    ReplaySource,
    StreamLoop,
    latency_summary,
    load_bundle,
    write_bundle,
)
from slipkit.runtime.bundle import Budget
from slipkit.runtime.preprocessing import Pipeline


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> LinearCase:
    return LinearCase(tmp_path_factory.mktemp("loop"))


@pytest.mark.parametrize("io_binding", [False, True])
def test_decisions_equal_numpy_reference(case: LinearCase, io_binding: bool) -> None:
    """Over a replay, the loop's scores and slip decisions equal a numpy reference of the same model."""
    loop = StreamLoop(load_bundle(case.path), io_binding=io_binding)
    result = loop.run(ReplaySource(case.frames, case.timestamps))
    expected_slip = case.scores >= case.threshold
    assert len(case.scores) == len(result.slip)
    np.testing.assert_allclose(case.scores, result.score, rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(expected_slip, result.slip)
    np.testing.assert_array_equal(
        np.arange(case.window - 1, len(case.frames)), result.frame
    )
    np.testing.assert_array_equal(case.timestamps[case.window - 1 :], result.timestamp)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_declared_equals_offline_debounce(tmp_path: Path, k: int) -> None:
    """Slip is declared exactly where slipkit.models.online.debounce fires on the per-frame decisions."""
    c = LinearCase(tmp_path, k=k)
    result = StreamLoop(load_bundle(c.path)).run(ReplaySource(c.frames, c.timestamps))
    np.testing.assert_array_equal(debounce(c.scores >= c.threshold, k), result.declared)
    assert k == result.summary()["debounce_k"]


def test_debounce_needs_consecutive_slip_frames(tmp_path: Path) -> None:
    """With k=2 a lone slip frame is never declared; the second of a pair is."""
    # window 1, one channel, score = x: the frame value is the score.
    man = manifest(1, threshold=0.5, channels=1, window=1, k=2)
    write_bundle(tmp_path / "b", linear_graph(np.ones(1), 0.0), man)
    loop = StreamLoop(load_bundle(tmp_path / "b"))
    values = [0, 1, 0, 1, 1, 1, 0, 1, 1]
    declared = [loop.step(np.array([v], dtype=np.float32)) for v in values]
    assert [False, False, False, False, True, True, False, False, True] == declared


@pytest.mark.parametrize(
    ("classes", "strict", "expected"),
    [
        (["static", "slip"], False, [False, True, True]),  # slip above, 0.5 counts
        (["static", "slip"], True, [False, False, True]),  # sklearn predict: > 0.5
        (["slip", "static"], False, [True, False, False]),  # sklearn's sorted classes_
        (["slip", "static"], True, [True, True, False]),
    ],
)
def test_threshold_rule_follows_class_order_and_strictness(
    tmp_path: Path, classes: list[str], strict: bool, expected: list[bool]
) -> None:
    """The score above the threshold means classes[1]; slip is declared only for the positive class."""
    decision = {
        "output": "score",
        "rule": "threshold",
        "classes": classes,
        "positive": "slip",
        "strict": strict,
    }
    man = manifest(1, threshold=0.5, channels=1, window=1, k=1, decision=decision)
    write_bundle(tmp_path / "b", linear_graph(np.ones(1), 0.0), man)
    loop = StreamLoop(load_bundle(tmp_path / "b"))
    assert expected == [
        loop.step(np.array([v], dtype=np.float32)) for v in (0.25, 0.5, 0.75)
    ]


@pytest.mark.parametrize(("window", "hop"), [(1, 1), (2, 1), (5, 1), (4, 3)])
def test_ring_buffer_windows_equal_sliding_window_view(
    tmp_path: Path, window: int, hop: int
) -> None:
    """After every frame the ring buffer holds the same window as sliding_window_view, and hops are kept."""
    man = manifest(3 * window, window=window, hop=hop)
    write_bundle(tmp_path / "b", linear_graph(np.ones(3 * window), 0.0), man)
    loop = StreamLoop(load_bundle(tmp_path / "b"))
    x = frames(23)
    expected = windows(x.astype(np.float64), window)
    decided = []
    for i, row in enumerate(x):
        out = loop.step(row, i / RATE_HZ)
        if i >= window - 1:
            np.testing.assert_array_equal(expected[i - window + 1], loop.window())
        if out is not None:
            decided.append(i)
    assert list(range(window - 1, len(x), hop)) == decided


def test_argmax_rule_decides_positive_class(tmp_path: Path) -> None:
    """The argmax rule declares slip where the positive class has the largest score."""
    rng = np.random.default_rng(3)
    w = rng.normal(size=(12, 2))
    man = manifest(
        12,
        threshold=None,
        decision={
            "output": "score",
            "rule": "argmax",
            "classes": ["slip", "static"],
            "positive": "slip",
        },
        k=1,
    )
    write_bundle(tmp_path / "b", linear_graph(w, [0.0, 0.2]), man)
    x = frames(60, seed=4)
    result = StreamLoop(load_bundle(tmp_path / "b")).run(
        ReplaySource(x, np.arange(60) / RATE_HZ)
    )
    logits = windows(x.astype(np.float64), 4).reshape(57, 12) @ w + [0.0, 0.2]
    np.testing.assert_array_equal(logits.argmax(axis=1) == 0, result.slip)
    np.testing.assert_allclose(logits[:, 0], result.score, atol=1e-5)


def test_argmax_needs_one_class_per_score(tmp_path: Path) -> None:
    """An argmax bundle naming three classes for a two-entry output is refused at decision.classes."""
    man = manifest(
        12,
        threshold=None,
        decision={
            "output": "score",
            "rule": "argmax",
            "classes": ["a", "b", "slip"],
            "positive": "slip",
        },
    )
    with pytest.raises(BundleError) as info:
        write_bundle(tmp_path / "b", linear_graph(np.ones((12, 2)), 0.0), man)
    assert "decision.classes" == info.value.field


def test_reset_forgets_window_and_debounce(case: LinearCase) -> None:
    """After reset the loop decides exactly as a fresh loop on the same frames."""
    loop = StreamLoop(load_bundle(case.path))
    first = loop.run(ReplaySource(case.frames, case.timestamps))
    loop.reset()
    again = loop.run(ReplaySource(case.frames, case.timestamps))
    np.testing.assert_array_equal(first.declared, again.declared)
    assert len(case.frames) == again.n_frames


def test_records_grow_past_capacity(case: LinearCase) -> None:
    """A small initial record capacity grows without losing decisions."""
    result = StreamLoop(load_bundle(case.path), capacity=4).run(
        ReplaySource(case.frames, case.timestamps)
    )
    np.testing.assert_array_equal(case.scores >= case.threshold, result.slip)


def test_latency_summary_counts_frames_over_budget() -> None:
    """Percentiles are in ms and frames over the p99 budget and over the frame period are
    counted; a stall confined to one block does not fail the latency rule, slow frames
    throughout do."""
    lat_ns = np.array(
        [100_000] * 98 + [600_000, 20_000_000]
    )  # 0.1 ms x98, 0.6 ms, 20 ms: both slow frames in the last of 5 blocks
    s = latency_summary(lat_ns, Budget(frame_period_ms=10.0, p99_ms=0.5))
    assert 0.1 == pytest.approx(s["latency_ms"]["p50"])
    assert 20.0 == pytest.approx(s["latency_ms"]["max"])
    assert (2, 1) == (s["over_budget"], s["over_period"])
    assert s["within_budget"] is True
    spread = np.array(([100_000] * 18 + [900_000] * 2) * 5)  # 10 % slow in every block
    assert latency_summary(spread, Budget(10.0, 0.5))["within_budget"] is False
    assert latency_summary([], Budget(10.0, 1.0))["within_budget"] is None


def test_latency_is_measured_from_arrival(case: LinearCase) -> None:
    """An arrival stamp given by the source is where the latency clock starts."""
    loop = StreamLoop(load_bundle(case.path))
    for i, row in enumerate(case.frames[:3]):
        loop.step(row, case.timestamps[i], arrival_ns=0)
    loop.step(
        case.frames[3], case.timestamps[3], arrival_ns=0
    )  # "arrived" at perf_counter 0: huge latency
    assert loop.result().latency_ns[0] > 1_000_000  # perf_counter_ns is far past 0


def test_pin_velocity_features_op_equals_training_features() -> None:
    """The pin_velocity_features op gives slipkit.features.pins' features of consecutive pin frames."""
    rng = np.random.default_rng(5)
    n_pins = 7
    pins = rng.normal(size=(3, 2 * n_pins))  # window of 3 frames, x block then y block
    pipe = Pipeline(
        [{"op": "pin_velocity_features", "missing_count": True}], pins.shape, "m.json"
    )
    xy = np.stack([pins[:, :n_pins], pins[:, n_pins:]], axis=-1)
    expected = velocity_features(pin_velocities(xy), missing_count=True)
    np.testing.assert_array_equal(expected, pipe(pins))
    assert (2, 2 * n_pins + 1) == pipe.out_shape


def test_diff_and_select_ops() -> None:
    """diff scales consecutive differences; select picks channels on the last axis."""
    x = np.arange(12.0).reshape(4, 3) ** 2
    pipe = Pipeline(
        [{"op": "select", "indices": [2, 0]}, {"op": "diff", "scale": 100.0}],
        x.shape,
        "m.json",
    )
    np.testing.assert_array_equal(np.diff(x[:, [2, 0]], axis=0) * 100.0, pipe(x))


def test_diff_needs_two_frames() -> None:
    """diff on a one-frame window is refused naming the step."""
    with pytest.raises(BundleError) as info:
        Pipeline([{"op": "diff"}], (1, 3), "m.json")
    assert "preprocessing[0].op" == info.value.field


@settings(max_examples=50, deadline=None)
@given(
    x=arrays(
        np.float64,
        (4, 3),
        elements=st.floats(-1e12, 1e12) | st.just(0.0) | st.just(np.nan),
    ),
    mean=arrays(np.float64, 3, elements=st.floats(-1e6, 1e6)),
    scale=arrays(np.float64, 3, elements=st.floats(1e-6, 1e6)),
)
def test_standardize_matches_numpy(
    x: np.ndarray, mean: np.ndarray, scale: np.ndarray
) -> None:
    """standardize equals (x - mean) / scale for extreme, zero and NaN inputs."""
    pipe = Pipeline(
        [{"op": "standardize", "mean": mean.tolist(), "scale": scale.tolist()}],
        (4, 3),
        "m.json",
    )
    np.testing.assert_array_equal((x - mean) / scale, pipe(x))


def _multiclass_bundle(root: Path, decision_extra: dict[str, Any]) -> Path:
    """A 4-class linear argmax bundle (classes n e s t) over 4-frame windows."""
    rng = np.random.default_rng(5)
    man = manifest(
        12,
        threshold=None,
        decision={
            "output": "score",
            "rule": "argmax",
            "classes": ["n", "e", "s", "t"],
            "positive": "n",
            **decision_extra,
        },
        k=1,
    )
    return write_bundle(root / "mc", linear_graph(rng.normal(size=(12, 4)), 0.0), man)


def test_argmax_any_slip_class_is_a_slip_decision_counted_per_class(
    tmp_path: Path,
) -> None:
    """slip_classes [n, e, s]: slip wherever the decided class is not t; the summary counts each class."""
    bundle = load_bundle(
        _multiclass_bundle(tmp_path, {"slip_classes": ["n", "e", "s"]})
    )
    x = frames(80, seed=6)
    result = StreamLoop(bundle).run(ReplaySource(x, np.arange(80) / RATE_HZ))
    w = np.random.default_rng(5).normal(size=(12, 4))
    decided = (windows(x.astype(np.float64), 4).reshape(77, 12) @ w).argmax(axis=1)
    expected = dict(
        zip("nest", np.bincount(decided, minlength=4).tolist(), strict=True)
    )
    summary = result.summary()
    assert expected == summary["decisions_by_class"]
    assert ["n", "e", "s"] == summary["slip_classes"]
    assert int(np.sum(decided != 3)) == summary["slip_decisions"]
    np.testing.assert_array_equal(decided != 3, result.slip)


def test_threshold_bundle_counts_its_two_classes(case: LinearCase) -> None:
    """A binary threshold bundle counts below / above as its two classes; slip is the positive one."""
    result = StreamLoop(load_bundle(case.path)).run(
        ReplaySource(case.frames, case.timestamps)
    )
    summary = result.summary()
    slip = int(result.slip.sum())
    expected = {"static": len(result.slip) - slip, "slip": slip}
    assert (expected, ["slip"]) == (
        summary["decisions_by_class"],
        summary["slip_classes"],
    )
