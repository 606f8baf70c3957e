"""TacTip pin-velocity features: velocities, circular-mean shift, NaN policy, labels."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.stats import circmean

from slipkit import config_dir
from slipkit.families.tactip.features import dataset_features, trial_features
from slipkit.families.tactip.physics import pin_layout
from slipkit.features import (
    SLIP,
    STATIC,
    circular_mean,
    feature_names,
    frame_labels,
    onset_velocity_index,
    pin_velocities,
    velocity_features,
    wrap_angle,
)
from slipkit.features.pins import RESULTANT_EPS
from slipkit.sim.commands import build_scene

FAST = settings(max_examples=60, deadline=None)

# A velocity component: exact (signed) zeros or a magnitude well inside float range, mm.
component = st.one_of(
    st.sampled_from([0.0, -0.0]),
    st.floats(1e-6, 10.0),
    st.floats(-10.0, -1e-6),
)


@st.composite
def velocity_frames(draw: st.DrawFn, min_pins: int = 1) -> np.ndarray:
    """Pin velocities (n_frames, N, 2) in mm/frame, with exact zeros likely."""
    n_frames = draw(st.integers(1, 4))
    n_pins = draw(st.integers(min_pins, 12))
    return draw(arrays(np.float64, (n_frames, n_pins, 2), elements=component))


def angle_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Absolute angular difference in rad, modulo 2 pi (so pi and -pi agree)."""
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


def reference_shift(dxy: np.ndarray) -> np.ndarray:
    """Shifted angles by another route: complex z rotated by the conjugate mean unit vector.

    Frames whose unit vectors cancel (resultant <= RESULTANT_EPS) have no mean
    direction and are not shifted, as documented.
    """
    z = dxy[..., 0] + 1j * dxy[..., 1]
    moving = z != 0
    unit = np.where(moving, z / np.where(moving, np.abs(z), 1.0), 0.0)
    total = unit.sum(axis=-1, keepdims=True)
    count = np.maximum(moving.sum(axis=-1, keepdims=True), 1)
    directed = np.abs(total) / count > RESULTANT_EPS
    mean = np.where(directed, total / np.where(directed, np.abs(total), 1.0), 1.0)
    return np.where(moving, np.angle(z * np.conj(mean)), 0.0)


def mean_resultant(dxy: np.ndarray) -> np.ndarray:
    """Resultant length (0..1) of the moving pins' unit velocity vectors, per frame."""
    moving = np.hypot(dxy[..., 0], dxy[..., 1]) > 0
    unit = np.exp(1j * np.arctan2(dxy[..., 1], dxy[..., 0]))
    total = np.abs(np.sum(np.where(moving, unit, 0.0), axis=-1))
    return total / np.maximum(moving.sum(axis=-1), 1)


def dtheta_of(dxy: np.ndarray) -> np.ndarray:
    return velocity_features(dxy, "dtheta")


# -- velocities ----------------------------------------------------------------------


def test_pin_velocities_are_frame_to_frame_differences():
    """Velocity frame k is frame k+1 minus frame k, one fewer than the frames."""
    frames = np.array([[[0.0, 0.0]], [[1.0, 2.0]], [[1.5, 1.0]]])
    expected = np.array([[[1.0, 2.0]], [[0.5, -1.0]]])
    np.testing.assert_array_equal(expected, pin_velocities(frames))


def test_pin_velocities_refuse_a_wrong_shape():
    """Pin frames must be (n_frames, N, 2)."""
    with pytest.raises(ValueError, match="N, 2"):
        pin_velocities(np.zeros((3, 4)))


# -- zero velocity ---------------------------------------------------------------------


@FAST
@given(n_frames=st.integers(2, 5), n_pins=st.integers(1, 127))
def test_all_pins_still_give_zero_finite_features(n_frames: int, n_pins: int):
    """A sensor at rest gives dr = 0 and dtheta = 0 for every pin (no atan2(0, 0) artefact)."""
    frames = np.broadcast_to(pin_layout(n_pins), (n_frames, n_pins, 2))
    out = velocity_features(pin_velocities(frames))
    np.testing.assert_array_equal(np.zeros((n_frames - 1, 2 * n_pins)), out)


@FAST
@given(n_pins=st.integers(1, 20), signs=st.data())
def test_signed_zero_velocities_have_no_direction(n_pins: int, signs: st.DataObject):
    """Exact zeros of either sign (atan2(-0., -0.) = -pi) give dtheta = 0."""
    dxy = signs.draw(
        arrays(np.float64, (1, n_pins, 2), elements=st.sampled_from([0.0, -0.0]))
    )
    for shift in (True, False):
        out = velocity_features(dxy, shift_angles=shift)
        np.testing.assert_array_equal(np.zeros((1, 2 * n_pins)), out)


@FAST
@given(dxy=velocity_frames())
def test_features_are_finite_and_still_pins_do_not_move_the_mean(dxy: np.ndarray):
    """Any mix of still and moving pins gives finite features; still pins get dtheta 0."""
    # The mean direction of nearly cancelling unit vectors is ill-conditioned
    # (error ~ eps / resultant): compare only clear directions or exact cancellation.
    resultant = mean_resultant(dxy)
    assume(np.all((resultant > 1e-5) | (resultant < 1e-12)))
    out = velocity_features(dxy)
    n = dxy.shape[1]
    assert np.all(np.isfinite(out))
    still = np.hypot(dxy[..., 0], dxy[..., 1]) == 0
    np.testing.assert_array_equal(np.zeros(int(still.sum())), out[..., n:][still])
    np.testing.assert_allclose(
        0.0, angle_error(reference_shift(dxy), out[..., n:]), atol=1e-9
    )


# -- circular mean and the +-pi wrap -----------------------------------------------------


@st.composite
def clusters_across_pi(draw: st.DrawFn) -> tuple[np.ndarray, float]:
    """Velocities (1, N, 2) whose angles lie within +-spread of a centre near +-pi."""
    n_pins = draw(st.integers(2, 40))
    centre = np.pi + draw(st.floats(-0.5, 0.5))
    spread = draw(st.floats(0.0, 1.0))
    offsets = draw(arrays(np.float64, n_pins, elements=st.floats(-1.0, 1.0)))
    radii = draw(arrays(np.float64, n_pins, elements=st.floats(0.01, 5.0)))
    ang = centre + spread * offsets
    dxy = np.stack([radii * np.cos(ang), radii * np.sin(ang)], axis=-1)[None]
    return dxy, spread


@FAST
@given(case=clusters_across_pi())
def test_shift_across_pi_matches_a_complex_reference(case: tuple[np.ndarray, float]):
    """Angles straddling +-pi are centred by the circular mean, as angle(z conj(u)) says."""
    dxy, spread = case
    out = dtheta_of(dxy)
    np.testing.assert_allclose(0.0, angle_error(reference_shift(dxy), out), atol=1e-9)
    # A plain mean of angles on both sides of +-pi would leave them near +-pi;
    # the circular shift keeps a cluster of half-width `spread` within 2 spread of 0.
    assert np.all(np.abs(out) <= 2.0 * spread + 1e-9)


@FAST
@given(dxy=velocity_frames(), alpha=st.floats(-2 * np.pi, 2 * np.pi))
def test_rotating_every_velocity_leaves_shifted_angles_unchanged(
    dxy: np.ndarray, alpha: float
):
    """A common rotation of all pin velocities changes neither dr nor the shifted dtheta."""
    assume(np.all(mean_resultant(dxy) > 1e-3))
    c, s = np.cos(alpha), np.sin(alpha)
    rotated = np.stack(
        [c * dxy[..., 0] - s * dxy[..., 1], s * dxy[..., 0] + c * dxy[..., 1]], axis=-1
    )
    n = dxy.shape[1]
    before, after = velocity_features(dxy), velocity_features(rotated)
    np.testing.assert_allclose(before[..., :n], after[..., :n], rtol=1e-12, atol=0)
    np.testing.assert_allclose(
        0.0, angle_error(before[..., n:], after[..., n:]), atol=1e-7
    )


@FAST
@given(angles=arrays(np.float64, st.integers(1, 30), elements=st.floats(-np.pi, np.pi)))
def test_circular_mean_agrees_with_scipy(angles: np.ndarray):
    """circular_mean matches scipy.stats.circmean wherever the angles have a direction."""
    assume(np.abs(np.mean(np.exp(1j * angles))) > 1e-4)
    expected = circmean(angles, high=np.pi, low=-np.pi)
    assert 1e-9 > angle_error(expected, circular_mean(angles))


def test_circular_mean_is_zero_without_a_direction():
    """Opposite angles, an empty selection and NaN-only input all give 0 rad."""
    assert 0.0 == circular_mean(np.array([0.5, 0.5 - np.pi]))
    assert 0.0 == circular_mean(np.array([1.0, 2.0]), where=np.array([False, False]))
    assert 0.0 == circular_mean(np.array([np.nan, np.nan]))
    np.testing.assert_allclose(
        [np.pi, 0.0],
        circular_mean(np.array([[np.pi, -np.pi], [0.3, np.pi + 0.3]]), axis=1),
        atol=1e-12,
    )


@FAST
@given(angles=arrays(np.float64, st.integers(1, 20), elements=st.floats(-1e3, 1e3)))
def test_wrap_angle_lands_in_half_open_range_and_keeps_the_direction(
    angles: np.ndarray,
):
    """wrap_angle maps into (-pi, pi], keeps the direction, and is idempotent."""
    out = wrap_angle(angles)
    assert np.all((out > -np.pi) & (out <= np.pi))
    np.testing.assert_allclose(0.0, angle_error(angles, out), atol=1e-9)
    np.testing.assert_array_equal(out, wrap_angle(out))
    assert np.pi == wrap_angle(np.array([-np.pi]))[0]


# -- missing pins ------------------------------------------------------------------------


@FAST
@given(
    frames=arrays(
        np.float64,
        st.tuples(st.integers(2, 4), st.integers(1, 10), st.just(2)),
        elements=st.floats(-20.0, 20.0),
    ),
    data=st.data(),
)
def test_nan_pins_never_leak_and_leave_other_pins_as_if_absent(
    frames: np.ndarray, data: st.DataObject
):
    """Missing pins give dr = dtheta = 0, are counted, and do not change the others."""
    gone = data.draw(arrays(np.bool_, frames.shape[:2]))
    frames = frames.copy()
    frames[gone] = np.nan
    dxy = pin_velocities(frames)
    n = dxy.shape[1]
    out = velocity_features(dxy, missing_count=True)
    assert np.all(np.isfinite(out))
    missing = np.isnan(dxy).any(axis=-1)
    np.testing.assert_array_equal(missing.sum(axis=1).astype(float), out[:, -1])
    np.testing.assert_array_equal(np.zeros(int(missing.sum())), out[:, :n][missing])
    np.testing.assert_array_equal(
        np.zeros(int(missing.sum())), out[:, n : 2 * n][missing]
    )
    for k in range(len(dxy)):
        keep = ~missing[k]
        if keep.any():
            alone = velocity_features(dxy[k][keep])
            m = int(keep.sum())
            np.testing.assert_allclose(alone[:m], out[k, :n][keep], rtol=1e-15)
            np.testing.assert_allclose(alone[m:], out[k, n : 2 * n][keep], atol=1e-12)


def test_variants_select_magnitudes_angles_or_both():
    """dr_dtheta is dr then dtheta (2N); dr and dtheta alone are N each; names match."""
    rng = np.random.default_rng(0)
    dxy = rng.normal(size=(3, 127, 2))
    both = velocity_features(dxy)
    np.testing.assert_array_equal(both[:, :127], velocity_features(dxy, "dr"))
    np.testing.assert_array_equal(both[:, 127:], velocity_features(dxy, "dtheta"))
    np.testing.assert_allclose(np.hypot(dxy[..., 0], dxy[..., 1]), both[:, :127])
    raw = velocity_features(dxy, "dtheta", shift_angles=False)
    np.testing.assert_allclose(np.arctan2(dxy[..., 1], dxy[..., 0]), raw)
    assert 254 == len(feature_names(127))
    assert ("dr0", "dtheta126", "n_missing") == (
        feature_names(127)[0],
        feature_names(127, missing_count=True)[-2],
        feature_names(127, missing_count=True)[-1],
    )
    with pytest.raises(ValueError, match="variant"):
        velocity_features(dxy, "xy")  # type: ignore[arg-type]


# -- labels and the onset frame -------------------------------------------------------------


@FAST
@given(
    n_frames=st.integers(0, 60),
    onset=st.one_of(st.none(), st.integers(0, 70)),
    n_slip=st.one_of(st.none(), st.integers(1, 8)),
)
def test_frame_labels_mark_n_slip_frames_from_the_onset(
    n_frames: int, onset: int | None, n_slip: int | None
):
    """'slip' exactly on onset .. onset + n_slip - 1 (or to the end), clipped to the trial."""
    labels = frame_labels(n_frames, onset, n_slip)
    idx = np.arange(n_frames)
    if onset is None:
        expected = np.zeros(n_frames, bool)
    elif n_slip is None:
        expected = idx >= onset
    else:
        expected = (idx >= onset) & (idx < onset + n_slip)
    np.testing.assert_array_equal(np.where(expected, SLIP, STATIC), labels)


def test_frame_labels_refuse_bad_arguments():
    """Negative onsets and n_slip < 1 are refused."""
    with pytest.raises(ValueError, match="onset_frame"):
        frame_labels(10, -1)
    with pytest.raises(ValueError, match="n_slip"):
        frame_labels(10, 2, 0)


@FAST
@given(n=st.integers(2, 400), rate=st.floats(30.0, 1000.0), u=st.floats(0.0, 1.0))
def test_onset_index_is_the_velocity_frame_whose_interval_holds_the_onset(
    n: int, rate: float, u: float
):
    """The onset velocity frame k satisfies t_k < onset <= t_{k+1}."""
    t = np.arange(n) / rate
    onset = t[0] + u * (t[-1] - t[0])
    assume(onset > t[0])
    k = onset_velocity_index(t, onset)
    assert k is not None
    assert t[k] < onset <= t[k + 1]


def test_onset_index_edge_cases():
    """Onset on a frame belongs to the interval ending there; NaN or late means no slip."""
    t = np.arange(5) / 100.0
    assert 1 == onset_velocity_index(t, t[2])
    assert 0 == onset_velocity_index(t, -1.0)
    assert onset_velocity_index(t, float("nan")) is None
    assert onset_velocity_index(t, 1.0) is None


# -- trials and datasets of the simulated scene ------------------------------------------------


@pytest.fixture(scope="module")
def sim_dataset():
    """Three trials of the tactip_gravity_drop scene as configured (missing pins included)."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=tactip_gravity_drop"])
    return build_scene(cfg.scene).simulate(3, seed=0)


def test_trial_features_align_rows_labels_and_times(sim_dataset):
    """One row per velocity frame, stamped with its later frame, 4 slip rows from the onset."""
    trial = sim_dataset.trial(sim_dataset.trial_ids[0])
    t = trial.streams["pins"]["t"].to_numpy()
    assert np.isnan(trial.streams["pins"].drop(columns="t").to_numpy()).any()
    X, y, times, onset = trial_features(trial)
    assert (len(t) - 1, 254) == X.shape
    assert np.all(np.isfinite(X))
    np.testing.assert_array_equal(t[1:], times)
    assert onset is not None
    assert t[onset] < trial.labels["slip_onset_s"] <= t[onset + 1]
    assert [onset, onset + 1, onset + 2, onset + 3] == np.flatnonzero(
        y == SLIP
    ).tolist()
    assert (len(t) - 1, 128) == trial_features(
        trial, variant="dr", missing_count=True
    ).X.shape


def test_dataset_features_concatenate_trials_with_their_ids(sim_dataset):
    """Rows of all trials in dataset order; groups name each row's trial."""
    feats = dataset_features(sim_dataset, n_slip=None)
    per_trial = [trial_features(tr, n_slip=None) for tr in sim_dataset]
    assert sum(len(p.y) for p in per_trial) == len(feats.X) == len(feats.groups)
    expected_groups = np.repeat(sim_dataset.trial_ids, [len(p.y) for p in per_trial])
    np.testing.assert_array_equal(expected_groups, feats.groups)
    np.testing.assert_array_equal(np.concatenate([p.X for p in per_trial]), feats.X)
    assert sum(len(p.y) - p.onset_index for p in per_trial) == int(
        np.sum(feats.y == SLIP)
    )


def test_feature_modules_import_without_pandas_sklearn_or_torch():
    """The runtime can import the feature and online-rule modules with numpy alone."""
    code = (
        "import sys, slipkit.features.pins, slipkit.models.online; "
        "print(sorted(m for m in ('pandas', 'sklearn', 'torch') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert "[]" == out.stdout.strip()
