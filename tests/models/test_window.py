"""Window classifiers (WindowMLP, WindowCNN, WindowGRU): scikit-learn contract, learning, seeds, cost."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.utils._param_validation import InvalidParameterError
from sklearn.utils.estimator_checks import parametrize_with_checks

from slipkit.models.window import (
    GRUModule,
    MLPModule,
    TemporalCNNModule,
    WindowCNN,
    WindowGRU,
    WindowMLP,
)

torch.set_num_threads(1)

# Small settings: the checks fit dozens of times on tiny data (a few seconds in all).
# A high learning rate lets 20 epochs reach scikit-learn's training-score bar (0.83).
SMALL = {"max_epochs": 10, "lr": 0.1, "batch_size": 64, "patience": 2}


@pytest.mark.slow  # ~110 checks, each fitting a net: 10-20 s on two shared cores
@parametrize_with_checks(
    [
        WindowMLP(hidden_units=8, **SMALL),
        WindowCNN(n_channels=1, filters=4, kernel_size=3, **SMALL),
    ],
    # None known: both pass every check with these settings.
    expected_failed_checks=lambda est: {},
)
def test_scikit_learn_estimator_contract(estimator, check):
    """Both window nets pass scikit-learn's estimator checks."""
    check(estimator)


def test_basic_contract_without_the_full_suite():
    """clone keeps params, predict before fit raises NotFittedError, bad params are named."""
    model = WindowMLP(hidden_units=7, random_state=1)
    assert {"hidden_units": 7, "random_state": 1}.items() <= clone(
        model
    ).get_params().items()
    with pytest.raises(NotFittedError):
        model.predict(np.zeros((2, 4)))
    with pytest.raises(InvalidParameterError, match="activation"):
        WindowMLP(activation="softsign").fit(np.zeros((4, 2)), [0, 1, 0, 1])


def two_class_windows(
    n_per_class: int = 40, width: int = 10, channels: int = 3, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Windows of counts near 2000 where class 'b' ramps up in channel 0 and 'a' stays flat.

    Returns flattened windows, labels and a trial id per window (4 windows per trial).
    """
    rng = np.random.default_rng(seed)
    n = 2 * n_per_class
    x = 2000.0 + rng.normal(0.0, 2.0, size=(n, width, channels))
    y = np.array(["a"] * n_per_class + ["b"] * n_per_class)
    x[y == "b", :, 0] += np.linspace(0.0, 20.0, width)
    groups = np.repeat(np.arange(n // 4), 4)
    return x.reshape(n, -1), y, groups


@pytest.mark.parametrize(
    "model",
    [
        WindowMLP(max_epochs=60, lr=0.01),
        WindowCNN(n_channels=3, max_epochs=60, lr=0.01),
        WindowGRU(n_channels=3, hidden_units=8, max_epochs=60, lr=0.01),
    ],
    ids=["mlp", "cnn", "gru"],
)
def test_separates_two_synthetic_classes_of_windows(model):
    """A ramp in one electrode vs none: held-out windows are classified (almost) perfectly."""
    X, y, groups = two_class_windows(seed=0)
    Xt, yt, _ = two_class_windows(seed=1)
    model.fit(X, y, groups=groups)
    assert ["a", "b"] == model.classes_.tolist()
    assert np.mean(model.predict(Xt) == yt) >= 0.95
    proba = model.predict_proba(Xt)
    np.testing.assert_allclose(np.ones(len(Xt)), proba.sum(axis=1), rtol=1e-5)


def test_same_seed_gives_identical_predictions_and_leaves_torch_rng_alone():
    """Two fits with random_state=3 agree exactly; the caller's torch RNG is untouched."""
    X, y, groups = two_class_windows(seed=2)
    torch.manual_seed(123)
    before = torch.random.get_rng_state()
    a = WindowMLP(max_epochs=8, random_state=3).fit(X, y, groups=groups)
    b = clone(a).fit(X, y, groups=groups)
    assert torch.equal(before, torch.random.get_rng_state())
    np.testing.assert_array_equal(a.predict_proba(X), b.predict_proba(X))
    c = WindowMLP(max_epochs=8, random_state=4).fit(X, y, groups=groups)
    assert not np.array_equal(a.predict_proba(X), c.predict_proba(X))


def test_the_paper_mlp_has_1900_inputs_50_sigmoid_units_and_a_softmax():
    """W=100 x 19 electrodes: 1900*50+50 + 50*2+2 parameters; torch module reachable."""
    rng = np.random.default_rng(0)
    X = rng.normal(size=(20, 1900)).astype(np.float32)
    y = np.array(["linear", "rotational"] * 10)
    model = WindowMLP(max_epochs=1, validation_fraction=0.0).fit(X, y)
    assert isinstance(model.module_, MLPModule)
    assert 1900 * 50 + 50 + 50 * 2 + 2 == model.n_parameters_
    assert 2 * (1900 * 50 + 50 * 2) == model.flops_per_window_
    layers = [type(m).__name__ for m in model.module_.net]
    assert ["Linear", "Sigmoid", "Linear", "Softmax"] == layers
    assert model.validated_ is False
    assert model.n_epochs_ == 1


def test_cnn_reads_the_flattened_window_as_frames_by_electrodes():
    """WindowCNN reshapes W*C inputs into C channels x W frames; a wrong C is refused."""
    X, y, _ = two_class_windows(n_per_class=10, width=6, channels=3)
    model = WindowCNN(n_channels=3, filters=4, kernel_size=3, max_epochs=2).fit(X, y)
    assert isinstance(model.module_, TemporalCNNModule)
    assert 6 == model.width_
    conv = (3 * 4 * 3 + 4) + (4 * 4 * 3 + 4)
    assert conv + 4 * 2 + 2 == model.n_parameters_
    assert 2 * 6 * (3 * 4 * 3 + 4 * 4 * 3) + 2 * 4 * 2 == model.flops_per_window_
    with pytest.raises(ValueError, match="n_channels"):
        WindowCNN(n_channels=4).fit(X, y)


def test_validation_split_keeps_trials_whole_and_early_stopping_keeps_the_best_epoch():
    """With groups, validation rows are whole trials; the kept epoch has the lowest loss."""
    X, y, groups = two_class_windows(n_per_class=40)
    model = WindowMLP(max_epochs=30, patience=3, lr=0.01, random_state=0)
    model.fit(X, y, groups=groups)
    assert model.validated_ is True
    losses = model.net_.history[:, "valid_loss"]
    assert int(np.argmin(losses)) + 1 == model.best_epoch_
    assert model.n_epochs_ == len(losses)
    va = model._valid_split(np.repeat([0, 1], 40), groups, 0)
    assert va is not None
    assert set() == set(groups[va[0]]) & set(groups[va[1]])


def test_gru_steps_through_the_frames_from_a_zero_state():
    """The GRU reads (N, W*C) as W frames of C; its output is the state after the last frame."""
    torch.manual_seed(0)
    module = GRUModule(n_channels=3, width=4, n_classes=2, hidden_units=5).eval()
    x = torch.randn(2, 12)
    with torch.no_grad():
        state = torch.zeros(1, 5)
        for frame in x[0].reshape(4, 3):  # one step per frame, from zero
            _, h = module.gru(frame.reshape(1, 1, 3), state.reshape(1, 1, 5))
            state = h.reshape(1, 5)
        expected = module.head(state)
        np.testing.assert_allclose(expected.numpy(), module(x)[:1].numpy(), atol=1e-6)
    # three gates of (3 x 5 + 5 x 5) multiply-adds per frame, 4 frames, head 5 x 2
    assert 4 * 2 * 3 * (3 * 5 + 5 * 5) + 2 * 5 * 2 == module.flops_per_window()


def test_gru_rejects_a_width_that_is_not_whole_frames():
    """10 inputs are not whole frames of 3 electrodes: the error names n_channels."""
    X = np.zeros((8, 10))
    with pytest.raises(ValueError, match="n_channels=3"):
        WindowGRU(n_channels=3, max_epochs=1).fit(X, [0, 1] * 4)
