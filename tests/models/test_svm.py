"""TacTipSVM (scikit-learn contract, kernel scale) and the debounced online slip rule."""

from __future__ import annotations

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from sklearn.datasets import make_classification
from sklearn.metrics import accuracy_score, balanced_accuracy_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC
from sklearn.utils._param_validation import InvalidParameterError
from sklearn.utils.estimator_checks import parametrize_with_checks

from slipkit import config_dir
from slipkit.data import split_by_trial
from slipkit.families.tactip.features import dataset_features, trial_features
from slipkit.features import SLIP, STATIC
from slipkit.models import (
    TacTipSVM,
    debounce,
    detection_delay,
    first_detection,
    frames_to_ms,
)
from slipkit.models.svm import PAPER_BOX_CONSTRAINT, PAPER_KERNEL_SCALE
from slipkit.sim.commands import build_scene

PAPER_KS, PAPER_BC = PAPER_KERNEL_SCALE, PAPER_BOX_CONSTRAINT


# SVC's own known failure, inherited (scikit-learn lists it for SVC, meta-issue #16298).
SAMPLE_WEIGHT = "libsvm's sample_weight scales C per sample: not equivalent to repeating samples (as for sklearn's SVC)."


@parametrize_with_checks(
    [
        TacTipSVM(),
        TacTipSVM(kernel="linear", class_weight="balanced"),
        TacTipSVM(C=1.0, gamma="scale", standardize=True, random_state=0),
    ],
    expected_failed_checks=lambda est: {
        "check_sample_weight_equivalence_on_dense_data": SAMPLE_WEIGHT,
    },
)
def test_scikit_learn_estimator_contract(estimator, check):
    """TacTipSVM passes scikit-learn's estimator checks (known SVC failure listed)."""
    check(estimator)


def test_kernel_scale_is_one_over_sqrt_gamma():
    """gamma = 1 / KS^2 both ways; the defaults are the paper's KS 38.8 and BC 686.6."""
    assert (
        TacTipSVM().get_params() == TacTipSVM.from_kernel_scale(PAPER_KS).get_params()
    )
    svm = TacTipSVM.from_kernel_scale(PAPER_KS, C=PAPER_BC)
    assert pytest.approx(1.0 / PAPER_KS**2, rel=1e-15) == svm.gamma
    assert pytest.approx(PAPER_KS, rel=1e-15) == svm.kernel_scale
    assert {"C": PAPER_BC, "kernel": "rbf"}.items() <= svm.get_params().items()
    with pytest.raises(AttributeError, match="kernel_scale_"):
        _ = TacTipSVM(gamma="scale").kernel_scale
    with pytest.raises(ValueError, match="kernel_scale"):
        TacTipSVM.from_kernel_scale(0.0)


@pytest.mark.parametrize("standardize", [True, False])
@pytest.mark.parametrize("gamma", ["scale", "auto", 0.02])
def test_fit_matches_a_plain_svc_pipeline_and_records_the_resolved_gamma(
    standardize: bool, gamma: float | str
):
    """Decisions equal SVC (behind StandardScaler if asked); gamma_ is SVC's resolved gamma."""
    X, y = make_classification(n_samples=120, n_features=8, random_state=0)
    X[:, 0] *= 50.0  # unequal feature scales, as dr (mm/frame) vs dtheta (rad)
    ours = TacTipSVM(C=3.0, gamma=gamma, standardize=standardize).fit(X, y)
    plain = SVC(C=3.0, gamma=gamma)
    ref = make_pipeline(StandardScaler(), plain) if standardize else plain
    ref.fit(X, y)
    np.testing.assert_allclose(ref.decision_function(X), ours.decision_function(X))
    np.testing.assert_array_equal(ref.predict(X), ours.predict(X))
    assert pytest.approx(plain._gamma, rel=1e-12) == ours.gamma_
    assert pytest.approx(1.0 / np.sqrt(ours.gamma_), rel=1e-12) == ours.kernel_scale_
    assert standardize == (ours.scaler_ is not None)


def test_linear_kernel_has_no_kernel_scale():
    """The linear kernel ignores gamma, so gamma_ and kernel_scale_ are None."""
    X, y = make_classification(n_samples=60, n_features=4, random_state=1)
    svm = TacTipSVM(kernel="linear").fit(X, y)
    assert (None, None) == (svm.gamma_, svm.kernel_scale_)


@pytest.mark.parametrize(
    ("params", "name"),
    [({"kernel": "poly"}, "kernel"), ({"C": 0.0}, "C"), ({"gamma": -1.0}, "gamma")],
)
def test_bad_hyper_parameters_are_refused_by_name(params: dict, name: str):
    """Declared constraints reject unknown kernels and non-positive C or gamma at fit."""
    X, y = make_classification(
        n_samples=20, n_features=3, n_informative=2, n_redundant=0, random_state=0
    )
    with pytest.raises(InvalidParameterError, match=f"'{name}'"):
        TacTipSVM(**params).fit(X, y)


# -- the online rule --------------------------------------------------------------------------


def naive_debounce(slip: np.ndarray, k: int) -> np.ndarray:
    """Reference: True where the last k decisions are all slip."""
    return np.array(
        [i >= k - 1 and bool(slip[i - k + 1 : i + 1].all()) for i in range(len(slip))]
    )


@settings(max_examples=100, deadline=None)
@given(slip=arrays(np.bool_, st.integers(0, 40)), k=st.integers(1, 6))
def test_debounce_fires_after_k_consecutive_slip_frames(slip: np.ndarray, k: int):
    """debounce is True exactly where k consecutive slip frames end; labels work too."""
    np.testing.assert_array_equal(naive_debounce(slip, k), debounce(slip, k))
    labels = np.where(slip, SLIP, STATIC)
    np.testing.assert_array_equal(naive_debounce(slip, k), debounce(labels, k))


def test_detection_delay_counts_frames_from_the_onset():
    """A perfect 2-frame rule fires 1 frame after the onset; early alarms are negative."""
    pred = np.array([STATIC] * 5 + [SLIP] * 4 + [STATIC] * 3)
    assert 1 == detection_delay(pred, onset_index=5, k=2)
    assert 5 == first_detection(pred, k=1)
    assert -3 == detection_delay(pred, onset_index=8, k=1)
    assert detection_delay(pred, onset_index=5, k=5) is None
    assert pytest.approx(1000.0 / 120.0) == float(frames_to_ms(1, 120.0))
    with pytest.raises(ValueError, match="k must"):
        debounce(pred, k=0)


# -- behaviour on the simulated gravity-drop scene ------------------------------------------------


@pytest.fixture(scope="module")
def drop_split():
    """12 simulated gravity-drop trials (seed 0), split in half by trial (seed 0)."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=tactip_gravity_drop"])
    ds = build_scene(cfg.scene).simulate(12, seed=0)
    train, _, test = split_by_trial(ds, test_size=0.5, seed=0).apply(ds)
    return train, test


def test_gaussian_svm_detects_slip_on_held_out_trials(drop_split):
    """The paper's Gaussian (dr, dtheta) SVM beats the majority class and fires near onset."""
    train, test = drop_split
    tr, te = dataset_features(train, n_slip=4), dataset_features(test, n_slip=4)
    assert not set(tr.groups) & set(te.groups)
    svm = TacTipSVM.from_kernel_scale(PAPER_KS, C=PAPER_BC, standardize=False)
    pred = svm.fit(tr.X, tr.y).predict(te.X)
    majority = float(np.mean(STATIC == te.y))
    # Measured (seed 0): accuracy 0.9954 vs majority 0.9889; balanced accuracy 0.915
    # (majority: 0.5). Seeds 1-4 give balanced accuracy 0.87-0.94.
    assert accuracy_score(te.y, pred) > majority
    assert balanced_accuracy_score(te.y, pred) > 0.8
    # Measured delays (k = 2, velocity frames): [1, 1, 1, 2, 1, 2]; 1 is the earliest
    # a 2-frame rule can fire after the onset frame.
    delays = []
    for trial in test:
        f = trial_features(trial, n_slip=4)
        delays.append(detection_delay(svm.predict(f.X), f.onset_index, k=2))
    near_onset = [d is not None and 0 <= d <= 3 for d in delays]
    assert sum(near_onset) >= 4, delays
