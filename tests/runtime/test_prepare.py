"""Prepared decisions: a bundle's prepare.onnx run on the frame before each decision (SlipTack speed)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from slipkit._files import sha256_bytes
from slipkit.export.detectors import NO_SCORE, check_detector_parity
from slipkit.export.parity import onnx_session
from slipkit.export.registry import ExportError
from slipkit.families.sliptack.export.detector import (
    SpeedSlipDetector,
    export_speed_slip_detector,
)
from slipkit.families.sliptack.export.speed import export_stick_slip_speed, graph_speeds
from slipkit.families.sliptack.speed import StickSlipSpeed
from slipkit.runtime import BundleError, StreamLoop, load_bundle, write_bundle
from slipkit.runtime.bundle import PREPARE_FILE, Budget, sign_manifest
from slipkit.runtime.cli import run
from slipkit.runtime.loop import LoopResult

RATE = 1000.0
W, HOP = 300, 10
THRESHOLD = 10.0
PARAMS: dict[str, Any] = {
    "rate_hz": RATE,
    "window": W,
    "hop": HOP,
    "detrend_frames": 300,
    "f_max_range": (15.0, 100.0),
    "min_peak_ratio": 0.6,
    "harmonics": "fundamental",
    "interpolate": True,
}


def _stick_slip(n: int, freq_hz: float, seed: int) -> NDArray[np.float64]:
    """A sawtooth nib signal (mm) on a drifting offset with read-out noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    saw = 0.05 * ((t * freq_hz) % 1.0)
    drift = 0.3 + 0.002 * np.cumsum(rng.normal(size=n))
    return drift + saw + 0.01 * rng.normal(size=n)


def _detector() -> SpeedSlipDetector:
    est = StickSlipSpeed(**PARAMS).fit(np.zeros((1, 1)), np.full(1, np.nan))
    return SpeedSlipDetector(speed=est, threshold=THRESHOLD).fit()


@pytest.fixture(scope="module")
def detector() -> SpeedSlipDetector:
    return _detector()


def _manifest(prepare: str | None) -> dict[str, Any]:
    man: dict[str, Any] = {
        "name": "sliptack",
        "frame": {
            "streams": ["nib"],
            "channels": ["deflection"],
            "shape": [1],
            "window": W,
            "hop": HOP,
            "rate_hz": RATE,
        },
        "preprocessing": [],
        "inputs": [{"name": "window", "dtype": "float32", "shape": [1, W, 1]}],
        "outputs": [{"name": "score"}],
        "decision": {
            "output": "score",
            "rule": "threshold",
            "column": 0,
            "classes": ["0", "1"],
            "positive": "1",
            "strict": False,
        },
        "threshold": THRESHOLD,
        "debounce": {"k": 1},
        "budget_ms": {"frame_period": 1.0, "p99": 0.1},
        "session": {"intra_op_num_threads": 1, "warmup": 2},
        "opset": 17,
        "producer": {"slipkit": "0.1.0"},
        "training": {"data_fingerprint": "abc123"},
    }
    if prepare is not None:
        man["prepare"] = {"tensor": prepare}
    return man


def _stream() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two stick-slip recordings back to back, a NaN frame and a 50 ms gap in them."""
    x = np.concatenate(
        [_stick_slip(1200, 37.0, seed=1), _stick_slip(1000, 22.0, seed=2)]
    )
    t = np.arange(len(x)) / RATE
    t[1500:] += 0.05  # a gap: the windows spanning it are skipped
    x[700] = np.nan  # a bad frame: flagged, its windows skipped
    return x[:, None], t


@pytest.fixture(scope="module")
def bundles(
    detector: SpeedSlipDetector, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("prepare")
    x, t = _stream()
    out = {}
    for name, prepare in (("whole", False), ("prepared", True)):
        g = export_speed_slip_detector(detector, prepare=prepare)
        out[name] = write_bundle(
            root / name,
            g.serialize(),
            _manifest(g.prepare_tensor if prepare else None),
            replay=(x, t),
            prepare=g.serialize_prepare(),
        )
    return out


def _loop_run(
    path: Path, *, direct: bool = False, io_binding: bool = True
) -> LoopResult:
    loop = StreamLoop(load_bundle(path), io_binding=io_binding)
    x, t = _stream()
    for v, ts in zip(x, t, strict=True):
        if direct:  # bypass the prepare step: every decision prepares late
            StreamLoop.step(loop, v, ts)
        else:
            loop.step(v, ts)
    return loop.result()


def test_prepared_graph_parity_with_batch_estimator(
    detector: SpeedSlipDetector,
) -> None:
    """The prepared graph's speeds agree with the batch estimator (1e-6 relative) on held-out recordings."""
    xs = [_stick_slip(1500, f, seed=10 + k) for k, f in enumerate((22.0, 37.0, 58.0))]
    X = np.concatenate(xs)[:, None]
    seg = np.concatenate([np.full(len(x), k) for k, x in enumerate(xs)])
    graph = export_speed_slip_detector(detector, prepare=True)
    rep = check_detector_parity(detector, graph, X, segments=seg)
    assert (True, 1.0, 0, True) == (
        rep["passed"],
        rep["agreement"],
        rep["n_finite_mismatch"],
        rep["max_rel_diff"] < 1e-6,
    )


def test_prepared_graph_scores_a_constant_window_as_no_score(
    detector: SpeedSlipDetector,
) -> None:
    """A constant window, prepared or not, has no spectral peak: NO_SCORE, as the batch estimator's NaN."""
    graph = export_speed_slip_detector(detector, prepare=True)
    win = np.full((1, W, 1), 0.4, dtype=np.float32)
    out = graph.run_windows(onnx_session(graph), win)
    assert NO_SCORE == float(out[0])


def test_prepared_and_whole_window_graphs_agree(detector: SpeedSlipDetector) -> None:
    """On the same windows the two graphs give the same speeds within 1e-6 relative."""
    x = _stick_slip(1300, 37.0, seed=3)
    ends = np.arange(W - 1, len(x), HOP)
    wins = np.stack([x[e - W + 1 : e + 1, None] for e in ends]).astype(np.float32)
    full = export_stick_slip_speed(detector.speed)
    prep = export_stick_slip_speed(detector.speed, prepare=True)
    a = graph_speeds(full.run_windows(onnx_session(full), wins))
    b = graph_speeds(prep.run_windows(onnx_session(prep), wins))
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    np.testing.assert_allclose(b[np.isfinite(a)], a[np.isfinite(a)], rtol=1e-6)
    assert (1, 2) == (len(full.model.graph.input), len(prep.model.graph.input))


def test_prepare_with_incremental_is_refused(detector: SpeedSlipDetector) -> None:
    """prepare needs the whole-window graph: with incremental=True the export refuses."""
    with pytest.raises(ExportError, match="prepare needs the whole-window graph"):
        export_stick_slip_speed(detector.speed, prepare=True, incremental=True)


def test_loop_scores_equal_the_whole_window_bundle(bundles: dict[str, Path]) -> None:
    """Through StreamLoop, with a bad frame and a gap, the prepared bundle decides on the same frames with the same scores."""
    whole, prep = _loop_run(bundles["whole"]), _loop_run(bundles["prepared"])
    np.testing.assert_array_equal(whole.frame, prep.frame)
    np.testing.assert_allclose(prep.score, whole.score, rtol=1e-5)
    np.testing.assert_array_equal(whole.slip, prep.slip)
    assert (1, 1, 0) == (whole.gaps, len(whole.bad_reason), prep.prepare_late)
    assert len(prep.prepare_latency_ns) >= len(prep.frame)


def test_prepare_runs_late_when_the_step_bypasses_it(bundles: dict[str, Path]) -> None:
    """A decision whose prepare did not run on the frame before runs it first: same scores, counted late."""
    ref = _loop_run(bundles["prepared"])
    late = _loop_run(bundles["prepared"], direct=True)
    np.testing.assert_array_equal(ref.score, late.score)
    assert (len(late.frame), 0) == (late.prepare_late, len(late.prepare_latency_ns))


def test_prepare_without_io_binding(bundles: dict[str, Path]) -> None:
    """The session.run path (no IOBinding) gives the IOBinding path's scores."""
    ref = _loop_run(bundles["prepared"])
    plain = _loop_run(bundles["prepared"], io_binding=False)
    np.testing.assert_array_equal(ref.score, plain.score)


def test_reset_starts_over(bundles: dict[str, Path]) -> None:
    """After reset() the loop decides as a fresh one on the same frames."""
    loop = StreamLoop(load_bundle(bundles["prepared"]))
    x, t = _stream()
    for v, ts in zip(x[:900], t[:900], strict=True):
        loop.step(v, ts)
    loop.reset()
    for v, ts in zip(x, t, strict=True):
        loop.step(v, ts)
    ref = _loop_run(bundles["prepared"])
    np.testing.assert_array_equal(ref.score, loop.result().score)


def test_within_budget_needs_the_prepare_frames() -> None:
    """The summary's within_budget is False when the prepare frames' p99 is over budget."""
    budget = Budget(frame_period_ms=1.0, p99_ms=0.1)
    n = 100
    base = {
        "frame": np.arange(n),
        "timestamp": np.zeros(n),
        "score": np.zeros(n),
        "slip": np.zeros(n, dtype=bool),
        "declared": np.zeros(n, dtype=bool),
        "latency_ns": np.full(n, 50_000, dtype=np.int64),
        "n_frames": n,
        "name": "b",
        "debounce_k": 1,
        "budget": budget,
    }
    slow = LoopResult(
        **base, prepare_latency_ns=np.full(n, 150_000, dtype=np.int64), has_prepare=True
    ).summary()
    fast = LoopResult(
        **base, prepare_latency_ns=np.full(n, 20_000, dtype=np.int64), has_prepare=True
    ).summary()
    plain = LoopResult(**base).summary()
    assert (False, n, True, True, None) == (
        slow["within_budget"],
        slow["prepare"]["over_budget"],
        fast["within_budget"],
        plain["within_budget"],
        plain["prepare"],
    )


def test_cli_reports_the_prepare_frames(
    bundles: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """slipkit-run prints the prepare frames' latency and writes them to --json."""
    run([str(bundles["prepared"]), "--json", str(tmp_path / "s.json")])
    summary = json.loads((tmp_path / "s.json").read_text())
    assert "prepare frames" in capsys.readouterr().out
    assert (0, True) == (
        summary["prepare"]["late"],
        summary["prepare"]["calls"] >= summary["decisions"],
    )


def _copy(src: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "b"
    shutil.copytree(src, dst)
    return dst


def _edit(bundle: Path, fn: Any) -> None:
    path = bundle / "manifest.json"
    man = json.loads(path.read_text())
    fn(man)
    path.write_text(json.dumps(sign_manifest(man)))


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda m: m.pop("prepare"), "files.prepare.onnx"),
        (lambda m: m["prepare"].update(tensor="nope"), "prepare.tensor"),
        (lambda m: m["prepare"].update(extra=1), "prepare.extra"),
        (lambda m: m["prepare"].update(tensor="window"), "prepare.tensor"),
        (
            lambda m: m.update(
                preprocessing=[{"op": "standardize", "mean": [0.0], "scale": [1.0]}]
            ),
            "prepare.tensor",
        ),
        (lambda m: m["files"].pop(PREPARE_FILE), "files"),
        (lambda m: m.update(prepare=[]), "prepare"),
        (lambda m: m["prepare"].update(tensor=5), "prepare.tensor"),
        (lambda m: m["prepare"].pop("tensor"), "prepare.tensor"),
    ],
)
def test_bad_prepare_fields_are_named(
    bundles: dict[str, Path], tmp_path: Path, edit: Any, field: str
) -> None:
    """A manifest whose prepare field, file list or preprocessing does not fit is refused, naming the field."""
    b = _copy(bundles["prepared"], tmp_path)
    _edit(b, edit)
    with pytest.raises(BundleError) as err:
        load_bundle(b)
    assert field == err.value.field


def test_changed_prepare_graph_is_refused(
    bundles: dict[str, Path], tmp_path: Path
) -> None:
    """A prepare.onnx that changed after writing fails its sha256, naming the file."""
    b = _copy(bundles["prepared"], tmp_path)
    data = bytearray((b / PREPARE_FILE).read_bytes())
    data[-1] ^= 1
    (b / PREPARE_FILE).write_bytes(bytes(data))
    with pytest.raises(BundleError, match="sha256") as err:
        load_bundle(b)
    assert str(b / PREPARE_FILE) == err.value.file


def test_prepare_graph_of_another_window_is_refused(
    detector: SpeedSlipDetector, bundles: dict[str, Path], tmp_path: Path
) -> None:
    """A prepare.onnx whose input is another window length is refused at load, naming the file and the shapes."""
    est = StickSlipSpeed(**{**PARAMS, "window": 200, "detrend_frames": 200}).fit(
        np.zeros((1, 1)), np.full(1, np.nan)
    )
    other = export_stick_slip_speed(est, threshold=THRESHOLD, prepare=True)
    b = _copy(bundles["prepared"], tmp_path)
    data = other.serialize_prepare()
    assert data is not None
    (b / PREPARE_FILE).write_bytes(data)
    _edit(b, lambda m: m["files"].update({PREPARE_FILE: sha256_bytes(data)}))
    with pytest.raises(BundleError, match=r"inputs\[0\]\.shape") as err:
        load_bundle(b)
    assert str(b / PREPARE_FILE) == err.value.file


def test_choose_session_and_pinned_sessions_rebuild_the_prepare_graph(
    bundles: dict[str, Path],
) -> None:
    """Session tuning measures a prepared bundle, and with_session rebuilds both graphs' sessions (same scores)."""
    from slipkit.runtime import choose_session
    from slipkit.runtime.session import SessionSpec

    b = load_bundle(bundles["prepared"])
    x, t = _stream()
    rows = choose_session(b, x, t, rounds=1, max_frames=600)
    pinned = b.with_session(SessionSpec(intra_op_num_threads=1, warmup=1))
    loop = StreamLoop(pinned)
    for v, ts in zip(x, t, strict=True):
        loop.step(v, ts)
    assert pinned.prepare_session is not b.prepare_session
    assert (True, True) == (len(rows) >= 1, pinned.prepare_session is not None)
    np.testing.assert_array_equal(
        _loop_run(bundles["prepared"]).score, loop.result().score
    )


@pytest.mark.parametrize("mode", ["loop", "threads"])
def test_a_prepared_bundle_in_a_hand(
    bundles: dict[str, Path], tmp_path: Path, mode: str
) -> None:
    """Beside a whole-window bundle in one hand, the prepared bundle makes the same decisions and reports its prepare frames."""
    out = tmp_path / "hand.json"
    run(
        [
            "--stream",
            f"a={bundles['prepared']}",
            "--stream",
            f"b={bundles['whole']}",
            "--hand-mode",
            mode,
            "--json",
            str(out),
        ]
    )
    rows = {s["stream"]: s for s in json.loads(out.read_text())["streams"]}
    assert rows["a"]["decisions"] == rows["b"]["decisions"]
    assert rows["a"]["slip_decisions"] == rows["b"]["slip_decisions"]
    assert (True, None) == (
        rows["a"]["prepare"]["calls"] >= rows["a"]["decisions"],
        rows["b"]["prepare"],
    )
