"""torch / skorch export (legacy exporter): dynamic batch, scalers inside, parity <= 1e-4."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import FunctionTransformer, StandardScaler
from torch import nn

from slipkit.export import (
    ExportError,
    check_parity,
    export,
    export_skorch_estimator,
    export_torch_module,
    find_torch_parts,
)
from slipkit.export.parity import run_graph

torch.set_num_threads(1)


class GRUHead(nn.Module):
    """(batch, steps, channels) -> GRU -> linear read-out of the last step."""

    def __init__(self, channels: int = 3, hidden: int = 5) -> None:
        super().__init__()
        self.gru = nn.GRU(channels, hidden, batch_first=True)
        self.out = nn.Linear(hidden, 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        seq, _ = self.gru(x)
        return self.out(seq[:, -1])


class ConvHead(nn.Module):
    """(batch, channels, steps) -> Conv1d -> ReLU -> mean over time -> linear."""

    def __init__(self, channels: int = 3) -> None:
        super().__init__()
        self.conv = nn.Conv1d(channels, 4, kernel_size=3, padding=1)
        self.out = nn.Linear(4, 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(torch.relu(self.conv(x)).mean(dim=-1))


@pytest.mark.parametrize(
    ("module", "shape"),
    [(GRUHead(), (7, 3)), (ConvHead(), (3, 7))],
    ids=["gru", "conv1d"],
)
def test_recurrent_and_convolutional_exports_keep_a_dynamic_batch(module, shape):
    """GRU and Conv1d graphs run at batch 1 and 9 and match torch to 1e-5."""
    torch.manual_seed(0)
    module = module.train()
    graph = export(module, input_shape=shape)
    assert ("batch", *shape) == graph.input_shape
    dim0 = graph.model.graph.input[0].type.tensor_type.shape.dim[0]
    assert "batch" == dim0.dim_param
    assert module.training  # the training flag is restored after export
    for batch in (1, 9):
        x = np.random.default_rng(batch).normal(size=(batch, *shape)).astype(np.float32)
        with torch.no_grad():
            ref = module.eval()(torch.from_numpy(x)).numpy()
        np.testing.assert_allclose(ref, run_graph(graph, x), atol=1e-5)
    report = check_parity(module.eval(), graph, x)
    assert (True, "forward") == (report["passed"], graph.score_method)


@pytest.fixture(scope="module")
def frames():
    """200 frames of 5 features with unequal scales, a class and a 2-D target."""
    rng = np.random.default_rng(0)
    X = (rng.normal(size=(200, 5)) * [1.0, 10.0, 100.0, 1.0, 0.1] + 3.0).astype(
        np.float32
    )
    y = (X[:, 0] + X[:, 1] / 10 > 3.0).astype(np.int64)
    Y = np.c_[X[:, 0] + 0.01 * X[:, 2], np.tanh(X[:, 1] / 10)]
    return X, y, Y


def test_skorch_pipeline_exports_scaler_net_and_softmax(frames):
    """StandardScaler + skorch classifier: graph == predict_proba (softmax inside) to 1e-4."""
    from skorch import NeuralNetClassifier

    X, y, _ = frames
    torch.manual_seed(0)
    net = NeuralNetClassifier(
        nn.Sequential(nn.Linear(5, 8), nn.Tanh(), nn.Linear(8, 2)),
        criterion=nn.CrossEntropyLoss,
        max_epochs=3,
        lr=0.1,
        train_split=None,
        verbose=0,
    )
    pipe = make_pipeline(StandardScaler(), net).fit(X, y)
    parts = find_torch_parts(pipe)
    np.testing.assert_allclose(pipe[0].mean_, parts.x_mean)
    assert parts.nonlinearity is not None
    graph = export(pipe[-1], input_shape=(5,))  # the registry knows skorch nets
    assert "predict_proba" == graph.score_method
    graph = export(
        pipe
    )  # Pipeline is skl2onnx's, but a skorch net at the end goes to torch
    assert (True, ("batch", 5)) == (graph.network, graph.input_shape)
    report = check_parity(pipe, graph, X)
    assert (True, 1.0) == (report["passed"], report["agreement"])
    assert 1e-4 >= report["max_abs_diff"]
    np.testing.assert_allclose(1.0, run_graph(graph, X).sum(axis=1), atol=1e-6)


class DuckRegressor:
    """A skorch-style regressor: module_ between x_scaler_ and y_scaler_ (as ForceMLP)."""

    def __init__(self, X: np.ndarray, Y: np.ndarray) -> None:
        torch.manual_seed(0)
        self.x_scaler_ = StandardScaler().fit(X)
        self.y_scaler_ = StandardScaler().fit(Y)
        self.module_ = nn.Sequential(
            nn.Linear(X.shape[1], 6), nn.Tanh(), nn.Linear(6, 2)
        )
        self.n_features_in_ = X.shape[1]

    def predict(self, X: np.ndarray) -> np.ndarray:
        xs = torch.as_tensor(self.x_scaler_.transform(X), dtype=torch.float32)
        with torch.no_grad():
            out = self.module_(xs).numpy()
        return self.y_scaler_.inverse_transform(out)


def test_duck_typed_estimator_gets_input_and_output_scaling(frames):
    """x_scaler_ and y_scaler_ become constant ops: graph == predict to 1e-4 (network rule)."""
    X, _, Y = frames
    est = DuckRegressor(X, Y)
    graph = export_skorch_estimator(est)
    assert (True, ("batch", 5)) == (graph.network, graph.input_shape)
    report = check_parity(est, graph, X)
    assert (True, False) == (report["passed"], report["has_decisions"])
    assert 1e-4 >= report["max_abs_diff"]


def test_slipkit_force_and_window_networks_export_with_parity(frames):
    """ForceMLP (y de-standardised) and WindowCNN (probabilities) pass parity through the generic path."""
    from slipkit.families.biotac.force import ForceMLP
    from slipkit.models.window import WindowCNN

    X, y, Y = frames
    force = ForceMLP(hidden=(6, 6), max_epochs=2, random_state=0).fit(X, Y)
    report = check_parity(force, export_skorch_estimator(force), X)
    assert report["passed"]
    assert 1e-4 >= report["max_abs_diff"]
    Xw = np.tile(X, (1, 2))  # 2 frames x 5 electrodes
    window = WindowCNN(n_channels=5, filters=4, max_epochs=2).fit(Xw, y)
    graph = export_skorch_estimator(window)
    assert "probabilities in classes_ order" == graph.score_meaning
    report = check_parity(window, graph, Xw)
    assert report["passed"]
    assert 1e-4 >= report["max_abs_diff"]


def test_parts_finder_names_what_it_cannot_use(frames):
    """A non-scaler step before the net, or no torch module at all, raise ExportError."""
    from skorch import NeuralNetRegressor

    X, _, Y = frames
    net = NeuralNetRegressor(
        nn.Linear(5, 2), max_epochs=1, train_split=None, verbose=0
    ).fit(X, Y.astype(np.float32))
    with pytest.raises(ExportError, match=r"step 'functiontransformer'"):
        find_torch_parts(make_pipeline(FunctionTransformer(), net))
    with pytest.raises(ExportError, match="StandardScaler has no torch module_"):
        find_torch_parts(StandardScaler().fit(X))
    graph = export_torch_module(nn.Linear(5, 2), input_shape=(5,), opset=18)
    assert 18 == graph.opset
