"""Window models to ONNX: statistics pipelines (skl2onnx + slipkit's converter), the GRU, the search."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.linear_model import LogisticRegression
from sklearn.neural_network import MLPClassifier
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from slipkit.export import check_parity, export
from slipkit.export.parity import run_graph
from slipkit.models.selection import CandidateSearch
from slipkit.models.window import WindowGRU
from slipkit.models.window_features import WindowStatistics

torch.set_num_threads(1)


def electrode_windows(
    n: int = 90, width: int = 6, channels: int = 4, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flattened windows of counts near 3000 (float32), three classes by the ramp's channel."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.array(["e", "n", "t"]), n // 3)
    x = 3000.0 + rng.normal(0.0, 5.0, (n, width, channels))
    ramp = np.linspace(0.0, 30.0, width)
    x[y == "e", :, 0] += ramp
    x[y == "n", :, 1] += ramp
    groups = np.tile(np.arange(6), n // 6)
    return x.reshape(n, -1).astype(np.float32), y, groups


@pytest.mark.parametrize("opset", [17, 18])
@pytest.mark.parametrize("subtract_first", [False, True])
@pytest.mark.parametrize("width", [1, 6])
def test_statistics_pipeline_graph_matches_predict_proba(opset, subtract_first, width):
    """Statistics + scaler + logistic regression: one graph, probabilities within 1e-4."""
    X, y, _ = electrode_windows(width=width)
    pipe = make_pipeline(
        WindowStatistics(n_channels=4, subtract_first=subtract_first),
        StandardScaler(),
        LogisticRegression(),
    ).fit(X, y)
    graph = export(pipe, opset=opset)
    assert (("batch", width * 4), ("e", "n", "t")) == (graph.input_shape, graph.classes)
    report = check_parity(pipe, graph, X)
    assert (True, 1.0) == (report["passed"], report["agreement"])


def test_statistics_alone_match_the_transformer_in_float32():
    """The converter's statistics equal WindowStatistics.transform (MLP pipeline as the carrier)."""
    X, y, _ = electrode_windows()
    pipe = make_pipeline(
        WindowStatistics(n_channels=4),
        StandardScaler(),
        MLPClassifier((8,), max_iter=2000, random_state=0),
    ).fit(X, y)
    graph = export(pipe)
    np.testing.assert_allclose(pipe.predict_proba(X), run_graph(graph, X), atol=1e-4)


def test_gru_exports_whole_window_in_class_out_with_a_dynamic_batch():
    """A fitted WindowGRU: graph input (batch, W*C), probabilities equal predict_proba."""
    X, y, groups = electrode_windows()
    gru = WindowGRU(n_channels=4, hidden_units=6, max_epochs=5, random_state=0)
    gru.fit(X, y, groups=groups)
    graph = export(gru)
    assert (("batch", 24), "predict_proba") == (graph.input_shape, graph.score_method)
    report = check_parity(gru, graph, X)
    assert (True, 1.0) == (report["passed"], report["agreement"])
    one = run_graph(graph, X[:1])  # batch 1, as the runtime calls it
    np.testing.assert_allclose(gru.predict_proba(X[:1]), one, atol=1e-5)


def test_search_exports_the_estimator_it_chose():
    """CandidateSearch -> the chosen, refitted pipeline's graph."""
    X, y, groups = electrode_windows()
    search = CandidateSearch(
        candidates={
            "stats_lr": make_pipeline(
                WindowStatistics(n_channels=4), StandardScaler(), LogisticRegression()
            )
        },
        verbose=False,
    ).fit(X, y, groups=groups)
    graph = export(search)
    report = check_parity(search, graph, X)
    assert (True, ("e", "n", "t")) == (report["passed"], graph.classes)
