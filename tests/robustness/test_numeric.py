"""Numerical hard cases of the learned models: extreme magnitudes, float32, constant columns.

Tolerances stated here are the ones ``docs/robustness.md`` quotes.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit.evaluate.metrics import regression_metrics
from slipkit.families.biotac.force import (
    ForceMLP,
    LocalLinearRegressor,
    WeightedNormalsRegressor,
)
from slipkit.models.svm import TacTipSVM
from slipkit.models.window import WindowCNN, WindowMLP

torch.set_num_threads(1)

#: Score tolerance of the scale-invariance checks (standardised SVM, absolute).
SVM_SCALE_ATOL = 1e-6
#: |decision_function| below which float32 and float64 inputs may decide differently.
SVM_FLOAT32_EPS = 1e-5


def _svm_data(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(80, 6))
    y = np.where(X[:, 0] + 0.3 * X[:, 1] > 0, "slip", "static")
    return X, y


@pytest.fixture(scope="module")
def svm_reference() -> dict[str, Any]:
    X, y = _svm_data()
    out: dict[str, Any] = {"X": X, "y": y}
    for name, params in {
        "standardised": {"standardize": True},
        "gamma_scale": {"gamma": "scale"},
    }.items():
        out[name] = (params, TacTipSVM(**params).fit(X, y).decision_function(X))
    return out


@settings(max_examples=25, deadline=None)
@given(
    exponent=st.integers(-12, 12),
    variant=st.sampled_from(["standardised", "gamma_scale"]),
)
def test_svm_scores_do_not_depend_on_the_input_scale(
    svm_reference: dict[str, Any], exponent: int, variant: str
) -> None:
    """A standardised (or gamma='scale') SVM fitted on inputs x 1e-12..1e12 scores as on the raw ones."""
    params, ref = svm_reference[variant]
    s = 10.0**exponent
    X, y = svm_reference["X"], svm_reference["y"]
    scores = TacTipSVM(**params).fit(X * s, y).decision_function(X * s)
    assert np.isfinite(scores).all()
    np.testing.assert_allclose(ref, scores, rtol=0, atol=SVM_SCALE_ATOL)


@pytest.mark.parametrize("exponent", [-12, -6, 6, 12])
def test_svm_scores_of_far_inputs_stay_finite_and_bounded(exponent: int) -> None:
    """Inputs 1e-12..1e12 times the training scale give finite scores within sum|dual| + |b|."""
    X, y = _svm_data()
    svm = TacTipSVM().fit(X, y)
    scores = svm.decision_function(X * 10.0**exponent)
    # Every RBF kernel value is in [0, 1], so |score| <= sum |alpha_i y_i| + |b|.
    bound = np.abs(svm.svc_.dual_coef_).sum() + abs(svm.svc_.intercept_[0])
    assert np.isfinite(scores).all()
    assert bound >= np.abs(scores).max()


def test_svm_float32_inputs_decide_as_float64_beyond_epsilon() -> None:
    """float32 inputs change scores by less than 1e-5 and no decision with |score| above it."""
    X, y = _svm_data()
    svm = TacTipSVM().fit(X, y)
    s64 = svm.decision_function(X)
    s32 = svm.decision_function(X.astype(np.float32))
    assert SVM_FLOAT32_EPS > np.abs(s64 - s32).max()
    sure = np.abs(s64) > SVM_FLOAT32_EPS
    np.testing.assert_array_equal(
        svm.predict(X)[sure], svm.predict(X.astype(np.float32))[sure]
    )


def test_standardised_svm_with_a_constant_column_is_finite() -> None:
    """A constant (e.g. a still pin's) column gets scale 1 and zero features, not a division by 0."""
    X, y = _svm_data()
    X[:, 2] = 5.0
    svm = TacTipSVM(standardize=True).fit(X, y)
    assert 1.0 == svm.scaler_.scale_[2]
    assert np.isfinite(svm.decision_function(X)).all()


def _graph_with_kernel_output(
    graph_model: onnx.ModelProto,
) -> tuple[ort.InferenceSession, str]:
    model = onnx.ModelProto()
    model.CopyFrom(graph_model)
    (kernel,) = [n.output[0] for n in model.graph.node if n.op_type == "Exp"]
    model.graph.output.append(
        onnx.helper.make_tensor_value_info(kernel, onnx.TensorProto.FLOAT, None)
    )
    sess = ort.InferenceSession(
        model.SerializeToString(), providers=["CPUExecutionProvider"]
    )
    return sess, kernel


def test_native_rbf_kernel_values_stay_in_unit_interval() -> None:
    """scikit-learn's kernel between support vectors and far or equal inputs lies in [0, 1]."""
    from sklearn.metrics.pairwise import rbf_kernel

    rng = np.random.default_rng(1)
    X = 30 * rng.normal(size=(200, 20))
    y = np.where(X[:, 0] + 10 * rng.normal(size=200) > 0, "slip", "static")
    svm = TacTipSVM(gamma=0.05).fit(X, y)
    sv = svm.svc_.support_vectors_
    for probe in (sv, sv * 1e12, sv * 1e-12):
        k = rbf_kernel(probe, sv, gamma=svm.gamma_)
        assert (0.0 <= k.min(), k.max() <= 1.0) == (True, True)


def test_exported_rbf_kernel_values_stay_in_unit_interval() -> None:
    """The exported graph's kernel values at the support vectors themselves are at most 1."""
    from slipkit.families.tactip.export.svm import export_tactip_svm

    rng = np.random.default_rng(1)
    X = 30 * rng.normal(size=(200, 20))
    y = np.where(X[:, 0] + 10 * rng.normal(size=200) > 0, "slip", "static")
    svm = TacTipSVM(gamma=0.05).fit(X, y)
    sess, kernel = _graph_with_kernel_output(export_tactip_svm(svm).model)
    sv = svm.svc_.support_vectors_.astype(np.float32)
    (k,) = sess.run([kernel], {sess.get_inputs()[0].name: sv})
    assert (0.0 <= k.min(), k.max() <= 1.0) == (True, True)


# -- window networks: softmax ---------------------------------------------------------
def _windows(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(60, 12))  # 4 frames x 3 channels
    X[:, 3] = 7.0  # a constant column (a resting electrode)
    return X, np.where(X[:, 0] > 0, "a", "b")


@pytest.fixture(scope="module")
def window_nets() -> dict[str, Any]:
    X, y = _windows()
    return {
        "mlp": WindowMLP(hidden_units=5, max_epochs=3, validation_fraction=0.0).fit(
            X, y
        ),
        "cnn": WindowCNN(
            n_channels=3, filters=4, max_epochs=3, validation_fraction=0.0
        ).fit(X, y),
    }


@pytest.mark.parametrize("net", ["mlp", "cnn"])
@pytest.mark.parametrize("exponent", [-12, -3, 0, 3, 12, 30])
def test_window_net_probabilities_stay_probabilities(
    window_nets: dict[str, Any], net: str, exponent: int
) -> None:
    """Inputs x 1e-12..1e30 give finite probabilities in [0, 1] summing to 1 (softmax never overflows)."""
    X, _ = _windows()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        p = window_nets[net].predict_proba(X * 10.0**exponent)
    assert np.isfinite(p).all()
    assert (0.0 <= p.min(), p.max() <= 1.0) == (True, True)
    np.testing.assert_allclose(np.ones(len(X)), p.sum(axis=1), atol=1e-6)


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize("net", ["mlp", "cnn"])
def test_window_net_refuses_values_beyond_float32_by_name(
    window_nets: dict[str, Any], net: str
) -> None:
    """A window beyond float32's range is a clear error naming float32, not a NaN probability."""
    X, _ = _windows()
    with pytest.raises(ValueError, match="float32"):
        window_nets[net].predict_proba(X * 1e39)


def test_force_mlp_constant_target_is_standardised_with_scale_one() -> None:
    """A constant force output is standardised with scale 1 (not a division by 0) and predicted finite."""
    rng = np.random.default_rng(2)
    X = rng.normal(size=(100, 4))
    Y = np.c_[X @ [1.0, 2.0, 3.0, 4.0], np.full(100, 2.0)]
    model = ForceMLP(max_epochs=5, random_state=0).fit(X, Y)
    assert 1.0 == model.y_scaler_.scale_[1]
    assert np.isfinite(model.predict(X)).all()


@pytest.mark.parametrize(
    "make",
    [
        lambda: ForceMLP(max_epochs=3, random_state=0),
        LocalLinearRegressor,
        WeightedNormalsRegressor,
    ],
    ids=["ForceMLP", "LocalLinearRegressor", "WeightedNormalsRegressor"],
)
def test_force_regressors_with_a_resting_electrode_stay_finite_at_any_scale(
    make: Any,
) -> None:
    """A constant electrode column, then inputs x 1e-12..1e12: every force estimate is finite, no warning."""
    rng = np.random.default_rng(0)
    X = rng.normal(size=(200, 19))  # BioTac: 19 electrodes
    X[:, 3] = 5.0
    Y = X[:, :3] @ np.ones((3, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = make().fit(X, Y)
        for exponent in (-12, 0, 12):
            assert np.isfinite(model.predict(X * 10.0**exponent)).all()


@pytest.mark.parametrize("net", ["mlp", "cnn"])
def test_window_net_float64_and_float32_inputs_give_identical_probabilities(
    window_nets: dict[str, Any], net: str
) -> None:
    """The nets compute in float32: float64 windows are cast first, so both inputs give the same numbers."""
    X, _ = _windows()
    np.testing.assert_array_equal(
        window_nets[net].predict_proba(X),
        window_nets[net].predict_proba(X.astype(np.float32)),
    )


# -- standardisation and metrics on constant signals -------------------------------------
@pytest.mark.parametrize(("value", "n"), [(1.0 / 3.0, 7), (1e12 / 3.0, 1000), (0.0, 5)])
def test_smse_of_a_constant_target_is_nan(value: float, n: int) -> None:
    """A constant truth has no variance: SMSE is NaN (JSON null) and RMSE stays finite."""
    truth = np.full(n, value)
    out = regression_metrics(truth, truth + 0.5, ["fz"])
    assert 0.5 == pytest.approx(out["rmse"]["fz"])
    assert np.isnan(out["smse"]["fz"])


@pytest.mark.parametrize("value", [0.1, 123.456])
def test_smse_of_a_constant_target_with_round_off_in_its_variance_is_nan(
    value: float,
) -> None:
    """A constant whose numpy variance is round-off (0.1 x 1000: 1.9e-34) is still constant: SMSE is NaN."""
    truth = np.full(1000, value)
    assert np.var(truth) > 0  # the round-off this case is about
    assert np.isnan(regression_metrics(truth, truth + 0.5, ["fz"])["smse"]["fz"])
