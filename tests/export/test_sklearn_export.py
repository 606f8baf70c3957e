"""skl2onnx-based export of plain scikit-learn estimators and Pipelines, checked in onnxruntime."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.datasets import make_classification, make_regression
from sklearn.linear_model import LinearRegression, LogisticRegression, Ridge
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC, LinearSVC

from slipkit.export import ExportError, check_parity, export, export_sklearn
from slipkit.export.parity import onnx_session, run_graph


@pytest.fixture(scope="module")
def binary():
    """120 frames of 6 features, two string classes, unequal feature scales."""
    X, y = make_classification(n_samples=120, n_features=6, random_state=0)
    X[:, 0] *= 50.0
    return X, np.where(y == 1, "static", "slip")


@pytest.mark.parametrize(
    "estimator",
    [
        LogisticRegression(max_iter=500),
        make_pipeline(StandardScaler(), LogisticRegression()),
    ],
    ids=["logistic", "scaler+logistic"],
)
def test_probabilities_match_predict_proba(binary, estimator):
    """Classifiers with predict_proba export probabilities in classes_ order (5 decimals)."""
    X, y = binary
    estimator.fit(X, y)
    graph = export(estimator)
    assert "predict_proba" == graph.score_method
    assert ("slip", "static") == graph.classes
    np.testing.assert_almost_equal(
        estimator.predict_proba(X), run_graph(graph, X), decimal=5
    )
    assert check_parity(estimator, graph, X)["passed"]


@pytest.mark.parametrize(
    "estimator",
    [SVC(C=1.0), make_pipeline(StandardScaler(), SVC(kernel="rbf")), LinearSVC()],
    ids=["svc", "scaler+svc", "linear_svc"],
)
def test_binary_decision_function_is_column_zero(binary, estimator):
    """Without predict_proba, output 'score' (column 0 of skl2onnx's scores) == decision_function."""
    X, y = binary
    estimator.fit(X, y)
    graph = export_sklearn(estimator)
    assert ("decision_function", "score", 0.0) == (
        graph.score_method,
        graph.score_output,
        graph.threshold,
    )
    ref = estimator.decision_function(X)
    ours = run_graph(graph, X)
    assert 1e-5 >= np.max(np.abs(ours - ref)) / np.max(np.abs(ref))
    report = check_parity(estimator, graph, X)
    assert (True, 1.0) == (report["passed"], report["agreement"])


def test_svc_scores_are_decision_function_then_its_negative(binary):
    """skl2onnx's SVC score output is [df, -df]: column 0 is sklearn's decision_function."""
    X, y = binary
    svc = SVC().fit(X, y)
    graph = export_sklearn(svc)
    raw_name = graph.output_names[1]
    raw = onnx_session(graph).run([raw_name], {"X": X.astype(np.float32)})[0]
    df = svc.decision_function(X)
    np.testing.assert_allclose(df, raw[:, 0], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(-df, raw[:, 1], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize(
    ("estimator", "n_targets"),
    [
        (LinearRegression(), 1),
        (Ridge(alpha=0.5), 3),
        (make_pipeline(StandardScaler(), Ridge()), 2),
    ],
    ids=["linear", "ridge-3", "scaler+ridge-2"],
)
def test_regression_outputs_match_predict(estimator, n_targets: int):
    """Regressors export predict (n_targets columns) to 1e-4 absolute; parity passes."""
    X, Y = make_regression(
        n_samples=80, n_features=5, n_targets=n_targets, noise=0.1, random_state=0
    )
    estimator.fit(X, Y)
    graph = export(estimator)
    assert ("predict", None) == (graph.score_method, graph.classes)
    ours = run_graph(graph, X).reshape(np.shape(Y))
    np.testing.assert_allclose(estimator.predict(X), ours, rtol=1e-5, atol=1e-3)
    report = check_parity(estimator, graph, X, atol=1e-3)
    assert (True, False) == (report["passed"], report["has_decisions"])


def test_multiclass_without_probabilities_is_refused():
    """A 3-class SVC (no predict_proba) has no single documented score: ExportError."""
    X, y = make_classification(
        n_samples=90, n_features=5, n_informative=3, n_classes=3, random_state=0
    )
    with pytest.raises(ExportError, match="3 classes and no predict_proba"):
        export_sklearn(SVC().fit(X, y))
    graph = export_sklearn(LogisticRegression(max_iter=500).fit(X, y))
    assert ("0", "1", "2") == graph.classes
    assert check_parity(LogisticRegression(max_iter=500).fit(X, y), graph, X)["passed"]
