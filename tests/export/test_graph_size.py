"""Graph sizes of the small exported models do not grow back, and the smaller graphs
and the loop's one-frame path give the same numbers (issue 16, docs/deploy.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.runtime.helpers import linear_graph, manifest

from slipkit.export import check_parity, export
from slipkit.export.parity import onnx_session
from slipkit.export.torch import find_torch_parts, fold_standardisation
from slipkit.families.biotac.export import force as _force  # noqa: F401  (registers the force exporters)
from slipkit.families.biotac.force import (
    ForceMLP,
    LocalLinearRegressor,
    WeightedNormalsRegressor,
)
from slipkit.families.fsr.export.touch_slip import export_fsr_touch_slip
from slipkit.families.fsr.touch_slip import FSRTouchSlip
from slipkit.families.sliptack.export.speed import export_stick_slip_speed
from slipkit.families.sliptack.speed import StickSlipSpeed
from slipkit.runtime import StreamLoop, load_bundle, write_bundle
from slipkit.runtime.preprocessing import Pipeline


def _ops(graph: Any) -> list[str]:
    return [n.op_type for n in graph.model.graph.node]


def _force_data(n: int = 300, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(0.0, 80.0, (n, 19))  # electrode counts after the baseline
    Y = X[:, :3] * 0.02 + np.tanh(X[:, 3:6] / 100.0) + rng.normal(0, 0.05, (n, 3))
    return X, Y


def test_fsr_graph_is_one_gemm_and_a_minimum() -> None:
    """The two-block FSR graph has 4 nodes on a float64 (batch, 10) window: one Gemm for the gate and the derivative, the gate as a minimum."""
    det = FSRTouchSlip(threshold=8.0, polarity="falling").fit(
        np.full((20, 1), 4.5), np.zeros(20, int)
    )
    graph = export_fsr_touch_slip(det, rest=4.5)
    expected = (["Gemm", "Add", "ReduceMin", "Clip"], ("batch", 10), "float64")
    assert expected == (_ops(graph), graph.input_shape, graph.input_dtype)


@pytest.mark.parametrize("gap", [-(2.0**-40), 0.0, 2.0**-40, 2.0**-10])
def test_fsr_graph_gate_is_strict_at_and_around_the_press_threshold(
    gap: float,
) -> None:
    """A press exactly at delta is untouched (NO_SCORE, the detector's -inf: its gate is strict); 2**-40 V above it the score is the detector's derivative."""
    from slipkit.export.detectors import graph_scores

    # block 4 and binary voltages: the graph's and numpy's block means are exact, so
    # gap 0 is an exact tie in both
    det = FSRTouchSlip(threshold=8.0, polarity="falling", block=4, delta=0.25).fit(
        np.full((20, 1), 4.5), np.zeros(20, int)
    )
    graph = export_fsr_touch_slip(det, rest=4.5)
    window = np.r_[np.full(4, 4.375), np.full(4, 4.5 - 0.25 - gap)]
    # 12 rest samples: the window is the recording's blocks 3 and 4 (blocks start at 0)
    ref = det.decision_function(np.r_[np.full(12, 4.5), window][:, None])[-1]
    out = onnx_session(graph).run(None, {graph.input_name: window[None]})[0]
    assert (gap > 0, ref) == (bool(np.isfinite(ref)), graph_scores(out)[0])


def test_force_graphs_have_few_nodes_and_reproduce_predict() -> None:
    """Weighted normals: one float32 Gemm; LWR: 7 float64 nodes; both within 1e-4 N of predict."""
    X, Y = _force_data()
    normals = WeightedNormalsRegressor().fit(X[:200], Y[:200])
    lwr = LocalLinearRegressor(n_fields=7, random_state=0).fit(X[:200], Y[:200])
    g_n, g_l = export(normals), export(lwr)
    assert ["Gemm"] == _ops(g_n)
    expected = ["Gemm", "Softmax", "Gemm", "Reshape", "Reshape", "MatMul", "Reshape"]
    assert (expected, "float64") == (_ops(g_l), g_l.input_dtype)
    assert "float32" == g_n.input_dtype
    for est, graph in ((normals, g_n), (lwr, g_l)):
        report = check_parity(est, graph, X[200:])
        assert (True, True) == (report["passed"], report["max_abs_diff"] <= 1e-4)


def test_force_mlp_graph_has_the_scalers_folded_and_the_module_unchanged() -> None:
    """The MLP graph is Gemm/Tanh only, equals predict to 1e-4 N, and the fitted module keeps its weights."""
    X, Y = _force_data()
    model = ForceMLP(hidden=(10, 10, 10), max_epochs=3, random_state=0).fit(X, Y)
    before = [p.detach().clone() for p in model.module_.parameters()]
    graph = export(model)
    assert {"Gemm", "Tanh"} == set(_ops(graph))
    after = list(model.module_.parameters())
    assert all(bool((a == b).all()) for a, b in zip(before, after, strict=True))
    report = check_parity(model, graph, X[:100])
    assert (True, True) == (report["passed"], report["max_abs_diff"] <= 1e-4)


def test_fold_standardisation_leaves_a_non_sequential_module_alone() -> None:
    """A module that is not a Sequential keeps its scaler ops (the parts come back as given)."""
    import torch

    class Net(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.lin = torch.nn.Linear(3, 1)

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return self.lin(x)

    parts = find_torch_parts(type("Est", (), {"module_": Net(), "n_features_in_": 3})())
    parts.x_mean, parts.x_scale = np.zeros(3), np.ones(3)
    assert parts is fold_standardisation(parts)


def _sliptack(**params: Any) -> StickSlipSpeed:
    base: dict[str, Any] = {
        "rate_hz": 1000.0,
        "window": 1000,
        "hop": 10,
        "f_max_range": (15.0, 100.0),
        "min_peak_ratio": 0.6,
        "detrend_frames": 300,
        "n_peaks": 10,
    }
    return StickSlipSpeed(**{**base, **params}).fit(
        np.zeros((1, 1)), np.full(1, np.nan)
    )


@pytest.mark.parametrize(
    ("params", "most"),
    [
        (
            {
                "harmonics": "fundamental",
                "interpolate": True,
                "min_peak_to_mean": 20.0,
            },
            73,
        ),
        ({}, 57),
    ],
    ids=["shipped", "paper"],
)
def test_sliptack_speed_graph_does_not_grow_back(
    params: dict[str, Any], most: int
) -> None:
    """The SlipTack speed graph of the shipped config has at most 73 nodes (96, then 84 before issue 16's peak search)."""
    graph = export_stick_slip_speed(_sliptack(**params))
    assert len(_ops(graph)) <= most


def test_prepared_sliptack_decision_graph_stays_small() -> None:
    """The shipped config's prepared export: at most 62 nodes on the decision frame and 20 in prepare.onnx (73 in one graph before)."""
    graph = export_stick_slip_speed(
        _sliptack(harmonics="fundamental", interpolate=True, min_peak_to_mean=20.0),
        prepare=True,
    )
    assert graph.prepare is not None
    assert (True, True) == (
        len(_ops(graph)) <= 62,
        len(graph.prepare.graph.node) <= 20,
    )


def test_baseline_first_subtracts_the_running_median_of_the_first_frames() -> None:
    """baseline_first gives x minus the median of the frames so far, frozen after n."""
    rng = np.random.default_rng(0)
    x = rng.normal(2000.0, 50.0, (30, 1, 19))
    op = Pipeline([{"op": "baseline_first", "frames": 10}], (1, 19), "m").ops[0]
    for i, frame in enumerate(x):
        expected = frame - np.median(x[: min(i + 1, 10), 0], axis=0)
        np.testing.assert_array_equal(expected, op(frame))


def _one_frame_bundle(root: Path) -> tuple[Path, np.ndarray, float]:
    rng = np.random.default_rng(1)
    w = rng.normal(size=3)
    man = manifest(
        3,
        window=1,
        k=1,
        preprocessing=[{"op": "baseline_first", "frames": 5}],
    )
    return write_bundle(root / "b", linear_graph(w, 0.25), man), w, 0.25


def test_one_frame_loop_flags_every_nonfinite_frame_and_scores_the_rest(
    tmp_path: Path,
) -> None:
    """A 1-frame window: NaN / +-inf in any channel is flagged, every other frame scores (x - baseline) @ w + b."""
    path, w, b = _one_frame_bundle(tmp_path)
    rng = np.random.default_rng(2)
    frames = rng.normal(size=(60, 3))
    bad = {20: (0, np.nan), 31: (1, np.inf), 42: (2, -np.inf)}
    for i, (ch, v) in bad.items():
        frames[i, ch] = v
    loop = StreamLoop(load_bundle(path))
    for i, f in enumerate(frames):
        loop.step(f, i / 100.0)
    res = loop.result()
    # the baseline: the median of the frames so far, until five have arrived
    base = np.array([np.median(frames[: min(i + 1, 5)], axis=0) for i in range(60)])
    good = np.array([i for i in range(60) if i not in bad])
    x = (frames[good] - base[good]).astype(np.float32).astype(np.float64)
    ref = x @ w + b
    assert (sorted(bad), ("nonfinite",) * 3) == (
        res.bad_frame.tolist(),
        res.bad_reason,
    )
    assert good.tolist() == res.frame.tolist()
    np.testing.assert_allclose(res.score, ref, rtol=1e-5, atol=1e-5)


def test_fsr_graph_scores_match_on_a_batch_and_one_window_at_a_time() -> None:
    """The FSR graph gives the same score for a window alone as inside a batch."""
    det = FSRTouchSlip(threshold=8.0, polarity="falling").fit(
        np.full((20, 1), 4.5), np.zeros(20, int)
    )
    graph = export_fsr_touch_slip(det, rest=4.5)
    sess = onnx_session(graph)
    wins = np.random.default_rng(3).uniform(3.0, 4.6, (50, 10))
    batch = sess.run(None, {graph.input_name: wins})[0]
    one = np.concatenate([sess.run(None, {graph.input_name: x[None]})[0] for x in wins])
    np.testing.assert_array_equal(batch, one)


def test_lwr_bundle_takes_float64_frames_and_scores_predict(tmp_path: Path) -> None:
    """An LWR bundle declares float64 in and out; StreamLoop's scores equal predict on the baseline-subtracted frames to 1e-9 N."""
    X, Y = _force_data()
    lwr = LocalLinearRegressor(n_fields=7, random_state=0).fit(X[:200], Y[:200])
    graph = export(lwr)
    man = manifest(
        19,
        channels=19,
        window=1,
        k=1,
        preprocessing=[{"op": "baseline_first", "frames": 5}],
        decision={"output": "score", "rule": "threshold", "column": 2},
    )
    man["inputs"] = [{"name": graph.input_name, "dtype": "float64", "shape": [1, 19]}]
    man["outputs"] = [{"name": graph.score_output}]  # dtype and shape from the graph
    bundle = load_bundle(write_bundle(tmp_path / "lwr", graph.serialize(), man))
    frames = 2000.0 + X[200:260]
    loop = StreamLoop(bundle)
    for i, f in enumerate(frames):
        loop.step(f, i / 300.0)
    res = loop.result()
    base = np.array([np.median(frames[: min(i + 1, 5)], axis=0) for i in range(60)])
    ref = lwr.predict(frames - base)[:, 2]
    assert ("float64", list(range(60))) == (
        bundle.manifest.outputs[0].dtype,
        res.frame.tolist(),
    )
    np.testing.assert_allclose(res.score, ref, rtol=0, atol=1e-9)
