"""benchmarks/bench_deploy.py's step-graph helpers: the state-bound bare call and its FLOPs."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from onnx import TensorProto, helper, numpy_helper
from tests.models.test_frame_gru import recordings
from tests.runtime.test_state import StepCase

from slipkit.export.frame_gru import export_frame_gru, write_frame_gru_bundle
from slipkit.models.frame_gru import FrameGRUDetector
from slipkit.runtime import StreamLoop, load_bundle

ROOT = Path(__file__).resolve().parents[2]
RATE_HZ = 300.0


def _bench() -> ModuleType:
    """benchmarks/bench_deploy.py as a module (benchmarks/ is not a package)."""
    spec = importlib.util.spec_from_file_location(
        "bench_deploy", ROOT / "benchmarks" / "bench_deploy.py"
    )
    assert spec is not None
    assert spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return _bench()


@pytest.fixture(scope="module")
def gru() -> FrameGRUDetector:
    X, y, seg = recordings(4)
    return FrameGRUDetector(hidden=6, chunk=32, epochs=3).fit(X, y, segments=seg)


def _loop_and_bare(
    bench: ModuleType, path: Path, frames: np.ndarray
) -> tuple[list[float], list[float]]:
    """Scores of StreamLoop and of bench_deploy's bare call on the same frames."""
    bundle = load_bundle(path)
    loop = StreamLoop(bundle)
    for i, row in enumerate(frames):
        loop.step(row, i / RATE_HZ)
    m = bundle.manifest
    (inp,) = m.inputs
    call = bench._bound_state(
        bundle.session, inp.name, m.decision.output, list(inp.static_shape), m.state
    )
    bare = [call(x.astype(inp.dtype)).item(m.decision.column) for x in frames]
    return loop.result().score.tolist(), bare


def test_bare_state_call_scores_as_the_loop_on_the_frame_gru(
    bench: ModuleType, gru: FrameGRUDetector, tmp_path: Path
) -> None:
    """The state-bound bare call, state carried h_out -> h_in, gives the loop's score on every frame of a GRU bundle."""
    X, _, seg = recordings(2, seed=5)
    held = X[seg == 0]
    write_frame_gru_bundle(
        gru,
        tmp_path / "gru",
        [held],
        name="gru",
        stream="s",
        channels=["a", "b"],
        rate_hz=RATE_HZ,
    )
    loop_scores, bare_scores = _loop_and_bare(bench, tmp_path / "gru", held)
    assert loop_scores == bare_scores


def test_bare_state_call_scores_as_the_loop_on_a_float32_step_graph(
    bench: ModuleType, tmp_path: Path
) -> None:
    """The bare call binds a float32 state as the loop does: equal scores frame by frame."""
    case = StepCase(tmp_path)
    frames = np.random.default_rng(1).normal(size=(40, 3))
    loop_scores, bare_scores = _loop_and_bare(bench, case.path, frames)
    assert loop_scores == bare_scores


def test_step_graph_flops_counts_both_projections_and_the_head(
    bench: ModuleType, gru: FrameGRUDetector
) -> None:
    """The frame GRU graph's FLOPs: 2 x 3H x (I + H) for the projections plus 2H for the head."""
    h, c = 6, 2
    expected = 2 * 3 * h * (c + h) + 2 * h
    assert expected == bench.step_graph_flops(export_frame_gru(gru).serialize())


def test_step_graph_flops_counts_a_gru_op_node(bench: ModuleType) -> None:
    """A graph with an ONNX GRU node counts 2 x 3H x (I + H) per step."""
    n_in, h = 5, 7
    rng = np.random.default_rng(0)
    w = numpy_helper.from_array(rng.normal(size=(1, 3 * h, n_in)), "W")
    r = numpy_helper.from_array(rng.normal(size=(1, 3 * h, h)), "R")
    node = helper.make_node("GRU", ["X", "W", "R"], ["", "h_out"], hidden_size=h)
    graph = helper.make_graph(
        [node],
        "gru",
        [helper.make_tensor_value_info("X", TensorProto.DOUBLE, [1, 1, n_in])],
        [helper.make_tensor_value_info("h_out", TensorProto.DOUBLE, [1, 1, h])],
        initializer=[w, r],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    assert 2 * 3 * h * (n_in + h) == bench.step_graph_flops(model.SerializeToString())
