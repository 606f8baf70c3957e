"""FSR probe slide: calibration, slip-event law, touch and disturbances, and the dataset."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit import config_dir
from slipkit.cli import main as cli_main
from slipkit.data import Trial, load_dataset
from slipkit.families.fsr.physics import (
    TABLE3_CORNERS,
    expected_slip_events,
    force_from_voltage,
    rest_voltage,
    voltage_from_force,
)
from slipkit.families.fsr.scene import FSRProbeSlide
from slipkit.sim import Scene, SimulationError
from slipkit.sim.commands import build_scene

BLOCK = 5  # the paper's stage 2: means of 5 samples
RATE = 2000.0


def build(*overrides: str) -> Scene:
    """The fsr_probe_slide scene from its real config with Hydra overrides."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="simulate", overrides=["scene=fsr_probe_slide", *overrides]
        )
    return build_scene(cfg.scene)


def block_derivative(trial: Trial) -> tuple[np.ndarray, pd.DataFrame]:
    """The paper's stage 2 (eq. 4): backward difference of 5-sample means (V/s), with
    the truth rows at each block's end."""
    v = trial.streams["fsr"]["voltage"].to_numpy()
    n = len(v) // BLOCK * BLOCK
    means = v[:n].reshape(-1, BLOCK).mean(axis=1)
    deriv = np.diff(means) * RATE / BLOCK
    truth = (
        trial.streams["truth_contact"]
        .iloc[BLOCK - 1 + BLOCK : n : BLOCK]
        .reset_index(drop=True)
    )
    return deriv, truth


def block_max(flags: pd.Series, n_blocks: int) -> np.ndarray:
    """Whether each block (aligned with :func:`block_derivative`) touches a flagged sample."""
    f = flags.to_numpy()[: (n_blocks + 1) * BLOCK].reshape(-1, BLOCK).max(axis=1)
    return np.maximum(f[1:], f[:-1]) > 0


# -- physics ------------------------------------------------------------------------------------
def test_calibration_maps_0_to_5_N_inside_0_to_5_V() -> None:
    """The default eq.-6 calibration maps 0-5 N into 0-5 V, the voltage falling with force."""
    force = np.linspace(0.0, 5.0, 501)
    volts = voltage_from_force(force)
    assert np.all((volts > 0.0) & (volts < 5.0))
    assert np.all(np.diff(volts) < 0)
    assert 4.5 == pytest.approx(rest_voltage())


@settings(max_examples=60, deadline=None)
@given(st.floats(0.0, 11.0))
def test_calibration_inverse_round_trips(force: float) -> None:
    """Eq. 6 applied to the inverted voltage gives the force back."""
    assert force == pytest.approx(
        float(force_from_voltage(voltage_from_force(force))), abs=1e-9
    )


def test_voltage_from_force_clips_outside_the_branch() -> None:
    """A negative force reads as rest; a force past the branch saturates at the output rail."""
    assert rest_voltage() == pytest.approx(float(voltage_from_force(-1.0)))
    assert 0.0 == pytest.approx(float(voltage_from_force(1e3)), abs=1e-12)


def test_count_law_fits_table3() -> None:
    """N = c F^alpha T^beta reproduces the four Table 3 corners within 3%."""
    for force, pass_s, count in TABLE3_CORNERS:
        assert count == pytest.approx(
            float(expected_slip_events(force, pass_s)), rel=0.03
        )
    rate_slow = expected_slip_events(1.2, 5.0) / 5.0
    rate_fast = expected_slip_events(1.2, 1.0) / 1.0
    assert rate_fast > 2.0 * rate_slow


# -- fsr_slip_events --------------------------------------------------------------------------------
def mean_events(force: float, pass_s: float, n: int = 12) -> float:
    """Mean slip events per pass over ``n`` trials at a fixed force and pass duration."""
    scene = build(
        f"scene.model.normal_force_N={force}",
        f"scene.model.pass_s={pass_s}",
        "scene.model.hold_s=0.3",
    )
    return float(
        np.mean([scene.run_trial(i, 0).labels["n_slip_events"] for i in range(n)])
    )


def test_slip_events_rise_with_force_and_per_second_with_speed() -> None:
    """More events at 4.7 N than at 1.2 N; fewer per 1 s pass than per 5 s pass, but more per second."""
    low_slow, low_fast = mean_events(1.2, 5.0), mean_events(1.2, 1.0)
    high_slow, high_fast = mean_events(4.7, 5.0), mean_events(4.7, 1.0)
    assert high_slow > low_slow
    assert high_fast > low_fast
    assert low_fast < low_slow
    assert high_fast < high_slow
    assert low_fast / 1.0 > low_slow / 5.0
    assert 37.6 == pytest.approx(low_slow, rel=0.15)
    assert 28.4 == pytest.approx(high_fast, rel=0.2)


def test_slip_events_are_sharp_positive_derivative_spikes() -> None:
    """Every slip event gives a stage-2 voltage derivative far above the sliding background."""
    scene = build("~scene.effects.fsr_disturbance")
    for i in range(3):
        trial = scene.run_trial(i, 1)
        deriv, truth = block_derivative(trial)
        onsets = np.flatnonzero(
            np.diff(np.r_[0, trial.streams["truth_contact"]["slip_event"]]) > 0
        )
        assert trial.labels["n_slip_events"] == len(onsets)
        peaks = [deriv[max(0, o // BLOCK - 2) : o // BLOCK + 2].max() for o in onsets]
        quiet = (truth["sliding"] == 1) & ~block_max(
            trial.streams["truth_contact"]["slip_event"], len(deriv)
        )
        assert min(peaks) > 3.0 * float(deriv[quiet.to_numpy()].max())


def test_removing_slip_events_removes_the_spikes() -> None:
    """Without fsr_slip_events there are no events and the slide's derivative stays at noise level."""
    scene = build("~scene.effects.fsr_slip_events", "~scene.effects.fsr_disturbance")
    trial = scene.run_trial(0, 1)
    assert 0 == trial.labels["n_slip_events"]
    assert 0 == int(trial.streams["truth_contact"]["slip_event"].sum())
    deriv, truth = block_derivative(trial)
    assert float(np.abs(deriv[(truth["sliding"] == 1).to_numpy()]).max()) < 4.0  # V/s


# -- fsr_disturbance ----------------------------------------------------------------------------------
def test_disturbances_stay_below_the_slip_band() -> None:
    """Disturbance bumps of both signs have no slip event and a derivative below every slip spike."""
    scene = build()
    signs = set()
    for i in range(6):
        trial = scene.run_trial(i, 2)
        truth = trial.streams["truth_contact"]
        dist = truth["disturbance"] == 1
        assert dist.any()
        assert 0 == int(truth["slip_event"][dist].sum())
        assert 0 == int(truth["sliding"][dist].sum())
        deriv, _ = block_derivative(trial)
        in_dist = block_max(truth["disturbance"], len(deriv))
        in_slip = block_max(truth["slip_event"], len(deriv))
        slip_peaks = [
            deriv[max(0, o // BLOCK - 2) : o // BLOCK + 2].max()
            for o in np.flatnonzero(np.diff(np.r_[0, truth["slip_event"]]) > 0)
        ]
        assert float(np.abs(deriv[in_dist & ~in_slip]).max()) < 0.5 * min(slip_peaks)
        fn = trial.labels["normal_force_N"]
        signs |= set(np.sign(truth["force"][dist] - fn).round().astype(int)) - {0}
    assert {-1, 1} == signs


def test_removing_disturbances_leaves_a_flat_hold() -> None:
    """Without fsr_disturbance the hold carries no bump: the force is flat and nothing is flagged."""
    scene = build("~scene.effects.fsr_disturbance")
    trial = scene.run_trial(0, 2)
    truth = trial.streams["truth_contact"]
    assert 0 == int(truth["disturbance"].sum())
    hold = (truth["t"] > 0.35) & (truth["t"] < 0.85)
    np.testing.assert_allclose(truth["force"][hold], trial.labels["normal_force_N"])


# -- fsr_touch ----------------------------------------------------------------------------------------
def test_touch_step_only_with_the_touch_effect() -> None:
    """With fsr_touch the voltage steps down from rest at the touch; without it there is no step."""
    with_touch = build("~scene.effects.fsr_disturbance").run_trial(0, 3)
    v = with_touch.streams["fsr"]
    t = v["t"].to_numpy()
    before = v["voltage"].to_numpy()[t < 0.29]
    after = v["voltage"].to_numpy()[(t > 0.32) & (t < 0.8)]
    expected_drop = rest_voltage() - float(
        voltage_from_force(with_touch.labels["normal_force_N"])
    )
    assert rest_voltage() == pytest.approx(float(before.mean()), abs=2e-3)
    assert expected_drop == pytest.approx(float(before.mean() - after.mean()), abs=5e-3)
    no_touch = build(
        "~scene.effects.fsr_disturbance", "~scene.effects.fsr_touch"
    ).run_trial(0, 3)
    w = no_touch.streams["fsr"]["voltage"].to_numpy()
    early, late = w[t < 0.29], w[(t > 0.32) & (t < 0.8)]
    assert 0.0 == pytest.approx(float(early.mean() - late.mean()), abs=2e-3)
    assert 0.0 == pytest.approx(
        float(no_touch.streams["truth_contact"]["force"][0])
        - no_touch.labels["normal_force_N"]
    )


# -- polarity and sharp knocks (issue 14) -------------------------------------------------------
def test_rising_polarity_mirrors_the_voltage_wherever_it_is_listed() -> None:
    """fsr_polarity=rising reads lo + hi - V: rest at 0.5 V, the touch raises the voltage, in any order."""
    fx = {"fsr_touch": {"rise_s": 0.01}, "fsr_slip_events": {}}
    falling = Scene("f", FSRProbeSlide(), fx).run_trial(0, 4)
    rising = Scene("f", FSRProbeSlide(), {**fx, "fsr_polarity": {"polarity": "rising"}})
    first = Scene(
        "f", FSRProbeSlide(), {"fsr_polarity": {"polarity": "rising"}, **fx}
    ).run_trial(0, 4)
    v_fall = falling.streams["fsr"]["voltage"].to_numpy()
    v_rise = rising.run_trial(0, 4).streams["fsr"]["voltage"].to_numpy()
    np.testing.assert_allclose(5.0 - v_fall, v_rise, atol=1e-12)
    np.testing.assert_allclose(v_rise, first.streams["fsr"]["voltage"], atol=1e-12)
    assert 0.5 == pytest.approx(float(v_rise[0]))
    assert float(v_rise[1000]) > 1.5  # pressed (0.5 s): above rest
    assert "rising" == first.meta["polarity"]


def test_sharp_knocks_have_millisecond_edges_and_15_to_50_percent_amplitude() -> None:
    """fsr_impulse_disturbance: both signs, |dF| 15-50 % of F, 5-50 ms long, and far steeper than bumps."""
    knock = {
        "count": [1, 3],
        "amplitude_frac": [0.15, 0.5],
        "rise_s": [0.001, 0.005],
        "duration_s": [0.005, 0.05],
    }
    model = FSRProbeSlide(hold_s=1.0)
    signs, steep, gentle = set(), [], []
    for i in range(8):
        for effects, out in (
            ({"fsr_impulse_disturbance": knock}, steep),
            ({"fsr_disturbance": {}}, gentle),
        ):
            trial = Scene("f", model, effects).run_trial(i, 5)
            truth = trial.streams["truth_contact"]
            fn = trial.labels["normal_force_N"]
            dist = truth["disturbance"].to_numpy() == 1
            rel = (truth["force"].to_numpy() - fn) / fn
            slope = np.abs(np.diff(truth["force"].to_numpy()))[dist[1:]]
            out.append(slope.max() * RATE / fn)
            if "fsr_impulse_disturbance" not in effects:
                continue
            assert 0.15 - 1e-9 <= np.abs(rel[dist]).max() <= 0.5 + 1e-9
            edges = np.flatnonzero(np.diff(np.r_[0, dist.astype(int), 0]))
            lengths = np.diff(edges)[::2] / RATE
            assert ((lengths >= 0.004) & (lengths <= 0.051)).all(), lengths
            signs |= set(np.sign(rel[dist][np.abs(rel[dist]) > 0.1]).astype(int))
    assert {-1, 1} == signs
    assert min(steep) > 5.0 * max(gentle)  # relative slope, 1/s


def test_force_effects_follow_dropped_frames() -> None:
    """A force effect after dropped_frames shifts the kept voltage samples by V(F_new) - V(F_old)."""
    model = build().model
    effects = {
        "dropped_frames": {"stream": "fsr", "probability": 0.3},
        "fsr_touch": {"rise_s": 0.0},
    }
    trial = Scene("fsr_probe_slide", model, effects).run_trial(0, 4)
    fsr, truth = trial.streams["fsr"], trial.streams["truth_contact"]
    assert len(fsr) < len(truth)
    expected = voltage_from_force(np.interp(fsr["t"], truth["t"], truth["force"]))
    np.testing.assert_allclose(fsr["voltage"], expected, atol=1e-9)


# -- datasets from the real config ----------------------------------------------------------------------
def test_scene_builds_a_reproducible_dataset() -> None:
    """The real config gives fsr + truth streams and labels, seeded reproducibly."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="simulate", overrides=["scene=fsr_probe_slide", "n_trials=3"]
        )
    scene = build_scene(cfg.scene)
    ds = scene.simulate(3, seed=0)
    assert "fsr" == ds.sensor
    assert ["fsr", "truth_contact"] == sorted(ds.streams)
    assert ("voltage",) == ds.streams["fsr"].channels
    assert ("force", "slip_event", "sliding", "disturbance") == ds.streams[
        "truth_contact"
    ].channels
    assert 2000.0 == ds.streams["fsr"].rate_hz
    assert ["slip_onset_s", "normal_force_N", "pass_s", "n_slip_events"] == list(
        ds.labels
    )
    assert () == ds.groups
    assert 3 == len(ds)
    for trial in ds:
        assert 0.9 == pytest.approx(trial.labels["slip_onset_s"])
        assert 1.2 <= trial.labels["normal_force_N"] <= 4.7
        assert 1.0 <= trial.labels["pass_s"] <= 5.0
    again = scene.simulate(3, seed=0)
    pd.testing.assert_frame_equal(ds.trials, again.trials)
    pd.testing.assert_frame_equal(ds.stream("fsr"), again.stream("fsr"))
    other = scene.simulate(3, seed=1)
    assert not ds.trials[["normal_force_N"]].equals(other.trials[["normal_force_N"]])


def test_cli_simulate_writes_a_loadable_dataset(tmp_path: object) -> None:
    """`slipkit simulate scene=fsr_probe_slide` writes a dataset that load_dataset reads back."""
    out = f"{tmp_path}/fsr"
    cli_main(
        [
            "simulate",
            "scene=fsr_probe_slide",
            "n_trials=2",
            "seed=3",
            f"out={out}",
            "progress=false",
            "summary=false",
            "scene.model.pass_s=1.0",
        ]
    )
    ds = load_dataset(out)
    assert 2 == len(ds)
    assert {"fsr", "truth_contact"} == set(ds.streams)


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"normal_force_N": [1.0, 50.0]}, "model.normal_force_N"),
        ({"pass_s": 0.0}, "model.pass_s"),
        ({"calibration": [1.0, 2.0]}, "model.calibration"),
        ({"calibration": [0.0, 0.0, 0.0, 1.0, 1.0]}, "model.calibration"),
        ({"rate_hz": -1.0}, "model.rate_hz"),
    ],
)
def test_bad_config_names_its_key(kwargs: dict[str, object], key: str) -> None:
    """An out-of-range config value raises SimulationError naming the config key."""
    with pytest.raises(SimulationError, match=key.replace(".", r"\.")):
        FSRProbeSlide(**kwargs)


def test_bad_effect_parameter_names_it() -> None:
    """A disturbance too long for the hold phase names the effect and the parameter."""
    scene = build("scene.model.hold_s=0.1")
    with pytest.raises(SimulationError, match="fsr_disturbance"):
        scene.run_trial(0, 0)
