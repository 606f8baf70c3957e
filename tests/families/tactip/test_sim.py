"""TacTip gravity-drop scene: pin layout, contact physics, effect signatures, config."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit import config_dir
from slipkit.cli import main as cli_main
from slipkit.data import load_dataset
from slipkit.data.dataset import Trial
from slipkit.families.tactip.physics import (
    contact_semi_axes,
    contact_weights,
    join_pins,
    mindlin_stretch,
    object_radius_mm,
    pin_channels,
    pin_layout,
    pins_in_rings,
    split_pins,
)
from slipkit.families.tactip.scene import TacTipGravityDrop
from slipkit.sim.commands import build_scene
from slipkit.sim.core import Scene, SimulationError

SCENE = "tactip_gravity_drop"


def compose_scene(*overrides: str) -> Scene:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={SCENE}", *overrides])
    return build_scene(cfg.scene)


def _scene_cfg(name: str):
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name="simulate", overrides=[f"scene={name}"]).scene


def scene_with(effects: dict, **model: object) -> Scene:
    return Scene(SCENE, TacTipGravityDrop(**model), effects)  # type: ignore[arg-type]


def pins_of(trial: Trial) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    p = trial.streams["pins"]
    x, y = split_pins(p.drop(columns="t").to_numpy())
    return p["t"].to_numpy(), x, y


def mean_speed(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Mean pin-velocity magnitude per frame (entry k: frame k -> k + 1), mm/frame."""
    return np.nanmean(np.hypot(np.diff(x, axis=0), np.diff(y, axis=0)), axis=1)


def resultant(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Circular resultant length of the pin-velocity angles per frame."""
    ang = np.arctan2(np.diff(y, axis=0), np.diff(x, axis=0))
    return np.abs(np.nanmean(np.exp(1j * ang), axis=1))


def onset_frame(t: np.ndarray, trial: Trial) -> int:
    return int(np.searchsorted(t, trial.labels["slip_onset_s"]))


# -- physics -------------------------------------------------------------------------


def test_default_layout_is_127_pins_in_six_hexagonal_rings():
    """The default layout has the paper's 127 pins, centre first, neighbours one pitch apart."""
    xy = pin_layout()
    assert (127, 2) == xy.shape
    assert 127 == pins_in_rings(6)
    np.testing.assert_allclose([0.0, 0.0], xy[0])
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    np.testing.assert_allclose(3.0, d.min(axis=1))
    np.testing.assert_allclose(6 * 3.0, np.hypot(xy[:, 0], xy[:, 1]).max())


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 200), pitch=st.floats(0.5, 5.0))
def test_layout_keeps_the_innermost_pins_for_any_count(n: int, pitch: float):
    """Any pin count gives that many pins, one pitch apart, the first ones of a full grid."""
    xy = pin_layout(n, pitch)
    assert (n, 2) == xy.shape
    if n > 1:
        d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        np.fill_diagonal(d, np.inf)
        assert pitch == pytest.approx(d.min(), rel=1e-9)
    np.testing.assert_array_equal(pin_layout(pins_in_rings(8), pitch)[:n], xy)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 50), frames=st.integers(1, 5))
def test_pin_channels_and_split_join_round_trip(n: int, frames: int):
    """Channels are x0..x{N-1} then y0..y{N-1}; join and split invert each other."""
    names = pin_channels(n)
    assert ("x0", f"x{n - 1}", "y0", f"y{n - 1}") == (
        names[0],
        names[n - 1],
        names[n],
        names[-1],
    )
    xy = np.arange(frames * n * 2, dtype=float).reshape(frames, n, 2)
    x, y = split_pins(join_pins(xy))
    np.testing.assert_array_equal(xy[..., 0], x)
    np.testing.assert_array_equal(xy[..., 1], y)


def test_object_labels_parse_to_radii():
    """'flat' is an infinite radius of curvature and 'r40' is 40 mm; others are refused."""
    assert math.inf == object_radius_mm("flat")
    assert 40.0 == object_radius_mm("r40")
    with pytest.raises(ValueError, match="r<radius mm>"):
        object_radius_mm("round")


def test_curvature_narrows_the_contact_across_x_only():
    """A sharper stimulus gives a narrower patch across its curvature, the same along its axis."""
    ax = {
        r: contact_semi_axes(np.array([2.0]), r, 20.0) for r in (math.inf, 80.0, 20.0)
    }
    assert ax[math.inf][0][0] > ax[80.0][0][0] > ax[20.0][0][0]
    assert ax[math.inf][1][0] == ax[20.0][1][0]
    w = contact_weights(pin_layout(), *ax[20.0], spread_mm=10.0)
    assert 1.0 == w[0, 0]
    assert np.all(w[0, 1:] <= 1.0)
    assert w[0].min() > 0
    assert 0.0 == contact_weights(pin_layout(), np.zeros(1), np.zeros(1), 10.0).max()


def test_mindlin_stretch_grows_from_zero_to_one_at_slip():
    """The normalised partial-slip displacement is 0 without load, 1 at full slip, and increasing."""
    rho = np.linspace(0.0, 1.0, 101)
    f = mindlin_stretch(rho)
    assert (0.0, 1.0) == (f[0], pytest.approx(f[-1]))
    assert np.all(np.diff(f) > 0)


# -- scene from the real config --------------------------------------------------------


def test_scene_from_config_has_streams_labels_and_groups():
    """The config builds a dataset of 254 pin channels at 120 Hz, grip truth, onset label, groups."""
    ds = compose_scene("n_trials=3").simulate(3, seed=0)
    assert ["pins", "truth_grip"] == sorted(ds.streams)
    assert 254 == len(ds.streams["pins"].channels)
    assert 120.0 == ds.streams["pins"].rate_hz
    assert ("object", "radius_mm", "speed_mm_s") == ds.groups
    assert ["slip_onset_s"] == list(ds.labels)
    assert set(ds.trials["object"]) <= {"flat", "r20", "r40", "r80"}
    for _, row in ds.trials.iterrows():
        assert object_radius_mm(row["object"]) == row["radius_mm"]
        assert 0.1 <= row["speed_mm_s"] <= 20.0
        assert 1.5 <= row["slip_onset_s"] <= 2.5
    assert 3 * 360 == len(ds.stream("pins"))


def test_same_seed_same_tables_and_different_seed_differs():
    """The same seed reproduces every table exactly; another seed gives other trials."""
    scene = compose_scene()
    a, b, c = (
        scene.simulate(2, seed=4),
        scene.simulate(2, seed=4),
        scene.simulate(2, seed=5),
    )
    pd.testing.assert_frame_equal(a.trials, b.trials)
    pd.testing.assert_frame_equal(a.stream("pins"), b.stream("pins"))
    assert not a.trials.drop(columns="trial_id").equals(
        c.trials.drop(columns="trial_id")
    )


def test_cli_simulate_writes_a_loadable_dataset(tmp_path):
    """`slipkit simulate scene=tactip_gravity_drop` writes a dataset that loads back."""
    out = tmp_path / "tactip"
    cli_main(
        [
            "simulate",
            f"scene={SCENE}",
            "n_trials=2",
            "seed=1",
            f"out={out}",
            "progress=false",
            "summary=false",
        ]
    )
    ds = load_dataset(out)
    assert ("tactip", 2) == (ds.sensor, len(ds))
    radii = [object_radius_mm(o) for o in ds.trials["object"]]
    assert radii == ds.trials["radius_mm"].tolist()
    assert 254 == len(ds.streams["pins"].channels)


def test_truth_grip_shows_friction_giving_way_at_onset():
    """mu_s F_n / (m g) falls through 1 at the onset; the object drops only after it."""
    trial = compose_scene().run_trial(0, seed=2)
    g = trial.streams["truth_grip"]
    on = trial.labels["slip_onset_s"]
    before, after = g[g.t < on], g[g.t >= on]
    assert np.all(before.hold_ratio >= 1.0 - 1e-12)
    assert np.all(after.hold_ratio < 1.0)
    assert 0.0 == before.object_drop.abs().max()
    assert np.all(np.diff(after.object_drop) > 0)


# -- effect signatures -------------------------------------------------------------------


def test_pin_speed_peaks_within_two_frames_of_onset():
    """With the config's effects, the mean pin-velocity magnitude peaks within 2 frames of onset."""
    scene = compose_scene()
    for i in range(6):
        trial = scene.run_trial(i, seed=3)
        t, x, y = pins_of(trial)
        peak = int(np.nanargmax(mean_speed(x, y))) + 1
        assert abs(peak - onset_frame(t, trial)) <= 2, trial.meta


def test_velocity_angles_align_at_onset_and_scatter_at_rest():
    """The circular resultant of pin-velocity angles is near 1 at the peak and low at rest."""
    scene = compose_scene()
    for i in range(6):
        trial = scene.run_trial(i, seed=7)
        _, x, y = pins_of(trial)
        r = resultant(x, y)
        assert r[int(np.nanargmax(mean_speed(x, y)))] > 0.9, trial.meta
        assert np.median(r[:60]) < 0.2, trial.meta


def test_snap_back_moves_pins_against_the_load_and_its_removal_removes_the_peak():
    """snap_back makes an upward onset spike; without it the onset frames look like rest."""
    fx = {
        "skin_stretch": {},
        "snap_back": {"tau_s": 0.02},
        "pin_jitter": {"sigma_mm": 0.005},
    }
    without = {k: v for k, v in fx.items() if k != "snap_back"}
    for i in range(4):
        ratios = []
        for effects in (fx, without):
            trial = scene_with(effects, speed_mm_s=0.1).run_trial(i, seed=11)
            t, x, y = pins_of(trial)
            k = onset_frame(t, trial)
            sp = mean_speed(x, y)
            ratios.append(sp[k - 1 : k + 2].max() / np.median(sp[: k - 10]))
            if effects is fx:
                up = np.nanmean(np.diff(y, axis=0)[k - 1 : k + 2], axis=1).max()
                assert up > 0.02
        assert ratios[0] > 3.0, ratios
        assert ratios[1] < 1.5, ratios


def test_skin_stretch_drifts_pins_slowly_in_the_load_direction_before_onset():
    """skin_stretch moves the pins down before onset in small steps; without it they do not."""
    with_fx = scene_with({"skin_stretch": {}}, speed_mm_s=0.1).run_trial(0, seed=5)
    bare = scene_with({}, speed_mm_s=0.1).run_trial(0, seed=5)
    t, _x, y = pins_of(with_fx)
    _, _, y0 = pins_of(bare)
    k = onset_frame(t, with_fx)
    drift = (y - y0).mean(axis=1)
    assert drift[k - 1] < drift[0] < 0.0
    assert np.all(np.diff(drift[:k]) <= 0.0)
    assert np.abs(np.diff(drift[:k])).max() < 0.01
    np.testing.assert_allclose(0.0, (y0 - y0[0]).mean(axis=1)[:k], atol=1e-12)


def test_slip_sliding_shakes_pins_only_after_onset():
    """slip_sliding adds incoherent pin motion after the onset and nothing before it."""
    noisy = scene_with(
        {"slip_sliding": {"sigma_mm": 0.03, "corr_s": 0.02, "ramp_s": 0.03}}
    ).run_trial(0, seed=6)
    bare = scene_with({}).run_trial(0, seed=6)
    t, x, y = pins_of(noisy)
    _, x0, _y0 = pins_of(bare)
    k = onset_frame(t, noisy)
    np.testing.assert_array_equal(x0[:k], x[:k])
    assert np.abs(x - x0)[k + 8 :].std() > 0.005
    assert resultant(x, y)[k + 8 :].mean() < 0.3


def test_pin_jitter_adds_noise_of_the_given_size_and_only_when_listed():
    """pin_jitter perturbs every coordinate with the configured s.d.; without it rest frames are still."""
    noisy = scene_with({"pin_jitter": {"sigma_mm": 0.01}}).run_trial(0, seed=8)
    bare = scene_with({}).run_trial(0, seed=8)
    _, x, y = pins_of(noisy)
    _, x0, y0 = pins_of(bare)
    assert 0.01 == pytest.approx(np.concatenate([x - x0, y - y0]).std(), rel=0.05)
    assert 0.0 == np.abs(np.diff(x0[:60], axis=0)).max()


def test_missing_pins_give_nan_pairs_only_when_listed():
    """missing_pins blanks x and y of a pin together at about the set rate; without it no NaN."""
    ds = compose_scene().simulate(2, seed=9)
    vals = ds.stream("pins").drop(columns=["trial_id", "t"]).to_numpy()
    x, y = split_pins(vals)
    np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
    assert 0.002 == pytest.approx(np.isnan(x).mean(), abs=0.0015)
    clean = compose_scene("~scene.effects.missing_pins").simulate(2, seed=9)
    assert not clean.stream("pins").isna().to_numpy().any()


def test_mindlin_creep_grows_from_the_contact_edge_before_onset_and_freezes_after():
    """mindlin_creep moves edge pins down before onset while the centre pin sticks; it holds after onset."""
    amp = 0.2
    creep = scene_with({"mindlin_creep": {"amplitude_mm": amp}}, speed_mm_s=0.1)
    trial = creep.run_trial(0, seed=5)
    bare = scene_with({}, speed_mm_s=0.1).run_trial(0, seed=5)
    t, x, y = pins_of(trial)
    _, x0, y0 = pins_of(bare)
    k = onset_frame(t, trial)
    dy = y - y0
    np.testing.assert_allclose(
        x0, x, atol=1e-12
    )  # gravity is straight down: no x creep
    assert 0.0 == np.abs(dy[:k, 0]).max()  # the centre pin is in the stick zone
    assert 0.0 > dy[k - 1].min() > -amp  # edge pins creep down, at most A
    assert dy[k - 1].mean() < dy[k // 2].mean() <= 0.0  # the creep grows towards onset
    np.testing.assert_allclose(dy[k:], np.broadcast_to(dy[k], dy[k:].shape))


def test_missing_pin_frames_blank_one_to_five_pins_in_the_given_share_of_frames():
    """missing_pin_frames blanks 1-5 pins (x and y together) in about p of the frames."""
    fx = {"missing_pin_frames": {"frame_probability": 0.1, "count": [1, 5]}}
    ds = Scene(SCENE, TacTipGravityDrop(), fx).simulate(4, seed=12)
    x, y = split_pins(ds.stream("pins").drop(columns=["trial_id", "t"]).to_numpy())
    np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
    per_frame = np.isnan(x).sum(axis=1)
    hit = per_frame[per_frame > 0]
    assert 0.1 == pytest.approx(len(hit) / len(per_frame), abs=0.03)
    assert {1, 2, 3, 4, 5} == set(hit.tolist())
    none = {"missing_pin_frames": {"frame_probability": 0.0, "count": [1, 5]}}
    clean = Scene(SCENE, TacTipGravityDrop(), none).simulate(1, seed=12)
    assert not clean.stream("pins").isna().to_numpy().any()


def test_331_pin_variant_uses_ten_full_rings():
    """The 331-pin hard variant lays out 10 hexagonal rings (331 = 1 + 3*10*11) at 60 FPS."""
    scene = build_scene(_scene_cfg("tactip_gravity_drop_hard_331"))
    trial = scene.run_trial(0, seed=0)
    assert 331 == pins_in_rings(10)
    assert 1 + 2 * 331 == trial.streams["pins"].shape[1]
    assert pytest.approx(1 / 60.0) == float(np.diff(trial.streams["pins"]["t"])[0])


# -- validation -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"press_mm": 1.0}, "press_mm"),
        ({"mu_k": 1.5}, "mu_k"),
        ({"objects": ["round"]}, "objects"),
        ({"onset_s": [1.0, 3.5]}, "onset_s"),
        ({"speed_mm_s": [0.0, 1.0]}, "speed_mm_s"),
        ({"n_pins": 0}, "n_pins"),
    ],
)
def test_bad_config_raises_naming_the_key(kwargs, key):
    """An out-of-range config value raises a SimulationError naming its key."""
    with pytest.raises(SimulationError, match=f"model.{key}"):
        TacTipGravityDrop(**kwargs)


def test_bad_effect_parameters_raise():
    """Effect parameters out of range raise a SimulationError naming the effect."""
    for effects in (
        {"snap_back": {"tau_s": 0.0}},
        {"missing_pins": {"probability": 2.0}},
        {"pin_jitter": {"sigma_mm": -1.0}},
        {"mindlin_creep": {"amplitude_mm": -0.1}},
        {"missing_pin_frames": {"frame_probability": 1.5}},
        {"missing_pin_frames": {"frame_probability": 0.1, "count": [3, 1]}},
    ):
        with pytest.raises(SimulationError, match=next(iter(effects))):
            scene_with(effects).run_trial(0, seed=0)
