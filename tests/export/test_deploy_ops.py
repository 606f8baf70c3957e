"""Force-model exporters and the runtime ops slipkit export writes, against the training code."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit.export import check_parity, export
from slipkit.export.deploy import decision_ends, graph_inputs
from slipkit.families.biotac.export import force as _force  # noqa: F401  (registers the force exporters)
from slipkit.families.biotac.force import LocalLinearRegressor, WeightedNormalsRegressor
from slipkit.families.biotac.force_task import _first_frames_median
from slipkit.features.windows import sliding_windows
from slipkit.runtime.preprocessing import Pipeline


def _force_data(n: int = 400, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(0.0, 80.0, (n, 20))  # 19 electrodes + one extra column (counts)
    Y = X[:, :3] * 0.02 + np.tanh(X[:, 3:6] / 100.0) + rng.normal(0, 0.05, (n, 3))
    return X, Y


@pytest.mark.parametrize(
    "est",
    [
        WeightedNormalsRegressor(),
        WeightedNormalsRegressor(fit_intercept=False),
        LocalLinearRegressor(n_fields=7, random_state=0),
        LocalLinearRegressor(n_fields=1, random_state=0),
    ],
    ids=["normals", "normals_no_offset", "lwr", "lwr_one_field"],
)
def test_force_exporters_pass_parity(est: object) -> None:
    """The hand-built force graphs reproduce predict to 1e-4 N on held-out frames."""
    X, Y = _force_data()
    est.fit(X[:300], Y[:300])  # type: ignore[attr-defined]
    graph = export(est)
    report = check_parity(est, graph, X[300:])
    assert report["passed"] is True
    assert report["max_abs_diff"] <= 1e-4


def test_one_dimensional_target_gives_a_flat_score() -> None:
    """A model fitted on a 1-D force exports a (batch,) score equal to its predict."""
    X, Y = _force_data()
    est = LocalLinearRegressor(n_fields=4, random_state=0).fit(X, Y[:, 0])
    graph = export(est)
    assert ("batch",) == tuple(
        d.dim_param or d.dim_value
        for d in graph.model.graph.output[0].type.tensor_type.shape.dim
    )
    assert check_parity(est, graph, X[:50])["passed"] is True


def test_baseline_first_matches_training_after_the_first_frames() -> None:
    """The runtime baseline equals ForceRegression's first-frames median once n frames have arrived."""
    rng = np.random.default_rng(1)
    frames = 2000 + rng.normal(0, 5, (60, 4)).cumsum(axis=0)
    n = 10
    table = pd.DataFrame(frames, columns=list("abcd"))
    table["trial_id"], table["t"] = "t0", np.arange(60) / 300.0
    trained = frames - _first_frames_median(table, list("abcd"), n)
    frame = {"shape": [4], "window": 1, "hop": 1}
    got, ends = graph_inputs(
        frames, frame, [{"op": "baseline_first", "frames": n, "hop": 1}], [4]
    )
    assert list(range(60)) == ends.tolist()
    np.testing.assert_allclose(got[n - 1 :], trained[n - 1 :], atol=1e-9)
    np.testing.assert_allclose(got[0], np.zeros(4), atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(
    width=st.integers(1, 6),
    hop=st.integers(1, 4),
    n_frames=st.integers(1, 30),
    mode=st.sampled_from(["raw", "window", "trial"]),
)
def test_runtime_windows_equal_training_windows(
    width: int, hop: int, n_frames: int, mode: str
) -> None:
    """The loop's windows after the exported steps equal sliding_windows of the same mode."""
    rng = np.random.default_rng(width * 100 + hop)
    frames = rng.normal(0, 1, (n_frames, 3))
    steps = {
        "raw": [],
        "window": [{"op": "subtract_first"}],
        "trial": [{"op": "baseline_first", "frames": 1, "hop": hop}],
    }[mode]
    frame = {"shape": [3], "window": width, "hop": hop}
    got, ends = graph_inputs(frames, frame, steps, [width * 3])
    want = sliding_windows(frames, width, hop=hop, mode=mode, dtype=np.float64)  # type: ignore[arg-type]
    assert want.end.tolist() == ends.tolist()
    np.testing.assert_allclose(got, want.X, atol=1e-12)


def test_subtract_op_removes_a_fixed_frame() -> None:
    """``subtract`` takes one fixed frame off every frame of the window, in float64."""
    ref = [10.0, -3.0]
    pipe = Pipeline([{"op": "subtract", "value": ref}], (2, 2), "m.json")
    x = np.array([[10.5, -3.0], [9.0, -2.0]])
    np.testing.assert_array_equal(x - np.array(ref), pipe(x))


def test_decision_ends_follow_the_loop_hop() -> None:
    """Decisions fall on window - 1 + j * hop, none before a window fills."""
    assert [3, 5, 7] == decision_ends(9, 4, 2).tolist()
    assert [] == decision_ends(2, 4, 1).tolist()


def test_graph_inputs_skip_windows_with_nan_as_the_loop_does() -> None:
    """With skip_nonfinite, every window holding a NaN frame is dropped."""
    frames = np.arange(12.0).reshape(6, 2)
    frames[2, 1] = np.nan
    _, ends = graph_inputs(
        frames, {"shape": [2], "window": 2, "hop": 1}, [], [4], skip_nonfinite=True
    )
    assert [1, 4, 5] == ends.tolist()


def test_graph_inputs_keep_nan_pins_as_missing() -> None:
    """For the pins stream NaN means a lost pin: only infinities skip a window, as in the loop."""
    frames = np.arange(12.0).reshape(6, 2)
    frames[2, 1] = np.nan
    frames[4, 0] = np.inf
    frame = {"streams": ["pins"], "shape": [2], "window": 2, "hop": 1}
    _, ends = graph_inputs(frames, frame, [], [4], skip_nonfinite=True)
    assert [1, 2, 3] == ends.tolist()
