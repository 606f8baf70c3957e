"""Force regressors of Su et al. 2015: weighted normals, skorch MLPs, local linear regression."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.base import clone
from sklearn.linear_model import Ridge
from sklearn.metrics import r2_score
from sklearn.preprocessing import StandardScaler
from sklearn.utils.estimator_checks import parametrize_with_checks

from slipkit.families.biotac.force import (
    ForceMLP,
    LocalLinearRegressor,
    WeightedNormalsRegressor,
)
from slipkit.families.biotac.physics import (
    ELECTRODE_NORMALS,
    linear_drive_matrix,
    weighted_normals_features,
    weighted_normals_scales,
)

torch.set_num_threads(1)


@parametrize_with_checks(
    [
        # One electrode on one axis: scikit-learn's checks pass a 1-D y, so the
        # analytic model is checked in its one-axis form (three axes need 3 columns).
        WeightedNormalsRegressor(normals=[[1.0]]),
        WeightedNormalsRegressor(normals=[[1.0], [-0.5]], fit_intercept=False),
        ForceMLP(hidden=(8,), max_epochs=30, lr=0.03, patience=5, random_state=0),
        LocalLinearRegressor(n_fields=4, random_state=0),
    ],
    expected_failed_checks=lambda est: {},
)
def test_scikit_learn_estimator_contract(estimator, check):
    """Every force regressor passes scikit-learn's estimator checks (no known failures)."""
    check(estimator)


def _probe(n: int, seed: int, gain=(60.0, 60.0, 60.0)) -> tuple[np.ndarray, ...]:
    """Forces and the exact linear electrode response ``E = A F`` of the simulator."""
    rng = np.random.default_rng(seed)
    force = rng.normal(0.0, [1.0, 1.5, 3.0], size=(n, 3))
    drive = linear_drive_matrix(gain)
    return force @ drive.T, force, weighted_normals_scales(drive)


@settings(max_examples=15, deadline=None)
@given(
    gain=st.tuples(*[st.floats(5.0, 200.0)] * 3),
    baseline=st.floats(-3000.0, 3000.0),
)
def test_weighted_normals_recovers_the_known_scales_and_absorbs_a_baseline(
    gain: tuple[float, float, float], baseline: float
):
    """On an exact linear response, the fit returns S = 1/diag(N^T A); a constant
    baseline b on every electrode shows up only as the offset -S (b sum_i N_i)."""
    E, F, scales = _probe(400, 0, gain)
    model = WeightedNormalsRegressor().fit(E + baseline, F)
    np.testing.assert_allclose(scales, model.scales_, rtol=1e-9)
    expected_offsets = -scales * baseline * ELECTRODE_NORMALS.sum(axis=0)
    np.testing.assert_allclose(expected_offsets, model.offsets_, atol=1e-6)
    np.testing.assert_allclose(F, model.predict(E + baseline), atol=1e-6)


def test_weighted_normals_without_intercept_is_the_bare_paper_form():
    """fit_intercept=False fits F_k = S_k sum E_i N_k,i: zero offsets, per-axis scales only."""
    E, F, scales = _probe(300, 1)
    model = WeightedNormalsRegressor(fit_intercept=False).fit(E, F)
    assert [0.0, 0.0, 0.0] == model.offsets_.tolist()
    np.testing.assert_allclose(scales, model.scales_, rtol=1e-9)
    np.testing.assert_allclose(
        weighted_normals_features(E) * scales, model.predict(E), atol=1e-9
    )


def test_weighted_normals_ignores_extra_columns_and_names_bad_shapes():
    """A DC-pressure column after the 19 electrodes is ignored; too few columns or a
    1-D force for three axes is refused with the reason."""
    E, F, _ = _probe(200, 2)
    pdc = np.random.default_rng(3).normal(size=(200, 1))
    with_pdc = WeightedNormalsRegressor().fit(np.hstack([E, pdc]), F)
    plain = WeightedNormalsRegressor().fit(E, F)
    np.testing.assert_allclose(plain.scales_, with_pdc.scales_)
    with pytest.raises(ValueError, match="19 electrode columns"):
        WeightedNormalsRegressor().fit(E[:, :5], F)
    with pytest.raises(ValueError, match="1 outputs but the normals have 3 axes"):
        WeightedNormalsRegressor().fit(E, F[:, 0])


def _smooth(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, size=(n, 3))
    y = np.column_stack([np.sin(X[:, 0]) + 0.5 * X[:, 1], np.tanh(X[:, 2]) * X[:, 0]])
    return X, y


def test_mlp_learns_a_smooth_map_on_unseen_points():
    """The 3x10 tanh network fits a smooth 2-output map: R^2 > 0.95 on fresh points."""
    X, y = _smooth(1500, 0)
    model = ForceMLP(
        hidden=(10, 10, 10), max_epochs=150, lr=0.01, patience=15, random_state=0
    ).fit(X, y)
    Xt, yt = _smooth(500, 1)
    assert r2_score(yt, model.predict(Xt)) > 0.95
    assert model.best_epoch_ <= model.n_epochs_


def test_mlp_same_seed_same_predictions_and_global_torch_rng_untouched():
    """Equal seeds give identical predictions, another seed differs, and fitting leaves
    torch's global random state where it was."""
    X, y = _smooth(300, 2)
    params = {"hidden": (6,), "max_epochs": 8, "lr": 0.01}
    state = torch.get_rng_state()
    a = ForceMLP(**params, random_state=7).fit(X, y).predict(X)
    assert torch.equal(state, torch.get_rng_state())
    b = ForceMLP(**params, random_state=7).fit(X, y).predict(X)
    c = ForceMLP(**params, random_state=8).fit(X, y).predict(X)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_mlp_uses_the_given_validation_set_and_exposes_its_torch_module():
    """validation_data drives early stopping; without validation all epochs run; the
    fitted module_ maps standardised float32 inputs to standardised outputs."""
    X, y = _smooth(400, 3)
    Xv, yv = _smooth(100, 4)
    with_val = ForceMLP(hidden=(5,), max_epochs=6, random_state=0).fit(
        X, y, validation_data=(Xv, yv)
    )
    assert with_val.best_valid_loss_ is not None
    no_val = ForceMLP(
        hidden=(5,), max_epochs=6, validation_fraction=0.0, random_state=0
    ).fit(X, y)
    assert (6, None) == (no_val.n_epochs_, no_val.best_valid_loss_)
    xs = torch.from_numpy(with_val.x_scaler_.transform(X).astype(np.float32))
    with torch.no_grad():
        out = with_val.module_(xs).numpy().astype(np.float64)
    np.testing.assert_allclose(
        with_val.predict(X), with_val.y_scaler_.inverse_transform(out), atol=1e-5
    )
    assert with_val.get_params() == clone(with_val).get_params()


def test_local_linear_with_one_field_is_a_global_ridge_regression():
    """With a single receptive field every weight is 1: predictions equal Ridge on the
    standardised, centred inputs."""
    X, y = _smooth(300, 5)
    model = LocalLinearRegressor(n_fields=1, alpha=0.5, random_state=0).fit(X, y)
    xs = StandardScaler().fit_transform(X)
    ref = Ridge(alpha=0.5).fit(xs - xs.mean(axis=0), y)
    np.testing.assert_allclose(
        ref.predict(xs - xs.mean(axis=0)), model.predict(X), atol=1e-8
    )


def test_local_linear_fits_a_non_linear_map_better_than_one_field():
    """More receptive fields follow a curved map more closely (and the fit is seeded)."""
    X, y = _smooth(1500, 6)
    Xt, yt = _smooth(400, 7)
    one = LocalLinearRegressor(n_fields=1, random_state=0).fit(X, y)
    many = LocalLinearRegressor(n_fields=25, random_state=0).fit(X, y)
    assert r2_score(yt, many.predict(Xt)) > r2_score(yt, one.predict(Xt)) + 0.05
    again = LocalLinearRegressor(n_fields=25, random_state=0).fit(X, y)
    np.testing.assert_array_equal(many.predict(Xt), again.predict(Xt))
