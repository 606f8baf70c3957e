"""SlipTack scenes: stick-slip physics, its signatures, and the datasets they produce."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from slipkit import config_dir
from slipkit.cli import main as cli_main
from slipkit.data import load_dataset
from slipkit.families.sliptack.effects import stick_slip
from slipkit.families.sliptack.physics import (
    ConstantSpeedMotion,
    cycles_constant_speed,
    cycles_quasi_static,
    drop_acceleration,
    natural_frequency,
    saturation_frequency,
    stick_slip_frequency,
    tau_slip_paper,
)
from slipkit.families.sliptack.scene import SlipTackDrop, SlipTackPull
from slipkit.sim import Scene, SimulationError
from slipkit.sim.commands import build_scene

M, K_L = 1.4e-5, 9.45  # the paper's nib (kg, N/m)
FN = 0.05  # per-nib normal load of the default configs (N)
CHERRY = (0.62, 0.50)  # (mu_s, mu_k) of the default configs


def build(scene: str, *overrides: str) -> Scene:
    """A scene from its real config with Hydra overrides."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={scene}", *overrides])
    return build_scene(cfg.scene)


def dominant_hz(x: np.ndarray, rate_hz: float) -> float:
    """Peak of the Hamming-windowed, zero-padded spectrum of a mean-removed signal (Hz)."""
    x = x - x.mean()
    n = 16 * len(x)
    spectrum = np.abs(np.fft.rfft(x * np.hamming(len(x)), n))
    freqs = np.fft.rfftfreq(n, 1.0 / rate_hz)
    spectrum[freqs < 1.0] = 0.0
    return float(freqs[np.argmax(spectrum)])


def pull_frequency(
    scene: Scene, seed: int = 0, settle_s: float = 0.5
) -> tuple[float, float]:
    """(measured dominant frequency, model frequency) of one pull trial (Hz)."""
    trial = scene.run_trial(0, seed)
    model = scene.model
    assert isinstance(model, SlipTackPull)
    nib = trial.streams["nib"]
    rate = model.rate_hz
    x = nib["deflection"].to_numpy()[
        nib["t"].to_numpy() >= model.pull_start_s + settle_s
    ]
    row = model.friction[str(trial.meta["material"])]
    f_model = stick_slip_frequency(
        trial.labels["speed_mm_s"] * 1e-3,
        trial.labels["normal_force_N"],
        row["mu_s"],
        row["mu_k"],
        M,
        K_L,
    )
    return dominant_hz(x, rate), float(f_model)


# -- closed-form relations ------------------------------------------------------------------
def test_paper_nib_constants() -> None:
    """The paper's nib has w0 = 822 rad/s (130.8 Hz) and a half period pi / w0 = 3.82 ms."""
    assert 821.6 == pytest.approx(float(natural_frequency(M, K_L)), abs=0.1)
    assert 130.8 == pytest.approx(float(saturation_frequency(M, K_L)), abs=0.05)
    assert 3.82e-3 == pytest.approx(float(tau_slip_paper(M, K_L)), abs=5e-6)


def test_frequency_forms_rise_and_saturate() -> None:
    """Both forms rise with speed towards their saturation; the paper's form overestimates."""
    v = np.linspace(0.01, 0.1, 10)
    exact = stick_slip_frequency(v, FN, *CHERRY, M, K_L, form="exact")
    paper = stick_slip_frequency(v, FN, *CHERRY, M, K_L, form="paper")
    assert np.all(np.diff(exact) > 0)
    assert np.all(np.diff(paper) > 0)
    for form in ("exact", "paper"):
        fast = stick_slip_frequency(1e6, FN, *CHERRY, M, K_L, form=form)
        assert float(saturation_frequency(M, K_L, form)) == pytest.approx(
            float(fast), rel=1e-3
        )
    assert 0.0 == float(stick_slip_frequency(0.0, FN, *CHERRY, M, K_L))


@settings(max_examples=40, deadline=None)
@given(
    v0=st.floats(0.005, 0.5),
    fn=st.floats(0.005, 0.5),
    mu_s=st.floats(0.2, 1.5),
    ratio=st.floats(0.3, 0.98),
)
def test_piecewise_cycles_have_the_exact_period(
    v0: float, fn: float, mu_s: float, ratio: float
) -> None:
    """After the first stick, every cycle of the integrated oscillator lasts 1 / f_exact."""
    mu_k = ratio * mu_s
    motion = ConstantSpeedMotion(v0, 0.0, fn)
    f = float(stick_slip_frequency(v0, fn, mu_s, mu_k, M, K_L))
    cycles = cycles_constant_speed(motion, 12.0 / f, mu_s, mu_k, M, K_L)
    np.testing.assert_allclose(cycles.periods_s, 1.0 / f, rtol=1e-9)
    u = cycles.evaluate(np.concatenate([cycles.break_s, cycles.restick_s[1:-1]]))
    np.testing.assert_allclose(
        u, np.r_[cycles.break_u, cycles.stick_u[1:]], rtol=1e-9, atol=1e-15
    )


def _solve_numerically(
    v0: float, fn: float, mu_s: float, mu_k: float, t_end: float, t_eval: np.ndarray
) -> np.ndarray:
    """Integrate the stick-slip ODE with solve_ivp, switching phases on events."""
    out = np.full(t_eval.shape, np.nan)
    t0, y, stuck = 0.0, np.array([0.0, v0]), True
    while t0 < t_end:
        if stuck:

            def rhs(t: float, y: np.ndarray) -> list[float]:
                return [v0, 0.0]

            def event(t: float, y: np.ndarray) -> float:
                return K_L * y[0] - mu_s * fn  # breakaway: spring force reaches mu_s Fn
        else:

            def rhs(t: float, y: np.ndarray) -> list[float]:
                return [y[1], (mu_k * fn - K_L * y[0]) / M]  # eq. 1

            def event(t: float, y: np.ndarray) -> float:
                return y[1] - v0  # re-stick: relative velocity back to zero

        event.terminal = True
        event.direction = 1.0
        sol = solve_ivp(
            rhs,
            (t0, t_end),
            y,
            events=event,
            dense_output=True,
            rtol=1e-11,
            atol=1e-14,
            max_step=2e-4,
        )
        t1 = float(sol.t_events[0][0]) if len(sol.t_events[0]) else t_end
        mask = (t_eval >= t0) & (t_eval < t1)
        out[mask] = sol.sol(t_eval[mask])[0]
        y = sol.sol(t1)
        y[1] = v0 if not stuck else y[1]
        t0, stuck = t1, not stuck
    return out


def test_piecewise_solution_matches_numerical_integration() -> None:
    """The piecewise-exact trajectory agrees with solve_ivp on the same ODE over 4 cycles."""
    v0 = 0.05
    t_end = 4.0 / float(stick_slip_frequency(v0, FN, *CHERRY, M, K_L))
    t_eval = np.linspace(0.0, t_end * 0.999, 3001)
    cycles = cycles_constant_speed(
        ConstantSpeedMotion(v0, 0.0, FN), t_end, *CHERRY, M, K_L
    )
    numerical = _solve_numerically(v0, FN, *CHERRY, t_end, t_eval)
    np.testing.assert_allclose(
        cycles.evaluate(t_eval), numerical, atol=1e-8
    )  # m; swing 1.3 mm


def test_quasi_static_equals_exact_at_constant_speed() -> None:
    """With no acceleration, the cycle-by-cycle loop reproduces the vectorised exact cycles."""
    motion = ConstantSpeedMotion(0.03, 0.1, FN)
    exact = cycles_constant_speed(motion, 1.0, *CHERRY, M, K_L)
    loop = cycles_quasi_static(motion, 1.0, *CHERRY, M, K_L)
    np.testing.assert_allclose(loop.break_s, exact.break_s, rtol=1e-12)
    np.testing.assert_allclose(loop.restick_s, exact.restick_s, rtol=1e-12)


def test_drop_acceleration_is_eq4() -> None:
    """Eq. 4: no deflection gives g; the deflection that balances the weight gives 0."""
    assert 9.81 == float(drop_acceleration(0.0, 0.45, 2000.0, 0.283))
    x_eq = 0.283 * 9.81 / (0.45 * 2000.0)
    assert 0.0 == pytest.approx(
        float(drop_acceleration(x_eq, 0.45, 2000.0, 0.283)), abs=1e-12
    )


# -- stick_slip signatures --------------------------------------------------------------------
@pytest.mark.parametrize("material", ["cherry", "basswood"])
def test_pull_frequency_follows_model_and_rises_with_speed(material: str) -> None:
    """Coupled mode: the dominant frequency is within 10% of 1/(tau_stick + tau_slip) and rises."""
    measured = []
    for speed in (15.0, 40.0, 70.0, 100.0):
        scene = build(
            "sliptack_pull",
            f"scene.model.speed_mm_s={speed}",
            f"scene.model.materials=[{material}]",
        )
        f_meas, f_model = pull_frequency(scene, seed=1)
        assert f_model == pytest.approx(f_meas, rel=0.10)
        measured.append(f_meas)
    assert np.all(np.diff(measured) > 0)


def test_individual_mode_aliases_fast_stick_slip() -> None:
    """At ~30 Hz the measured frequency differs from the true one whenever f > 15 Hz."""
    for speed in (40.0, 60.0, 90.0):
        scene = build(
            "sliptack_pull",
            "scene.model.rate_hz=30.0",
            "scene.model.duration_s=10.0",
            f"scene.model.speed_mm_s={speed}",
            "scene.model.materials=[cherry]",
        )
        f_meas, f_true = pull_frequency(scene, seed=2)
        assert f_true > 15.0
        assert abs(f_meas - f_true) > 0.1 * f_true


def _cycle_cv(material: str, speed: float) -> float:
    """Coefficient of variation of the steady cycle periods of one pull trial."""
    scene = build(
        "sliptack_pull",
        f"scene.model.materials=[{material}]",
        f"scene.model.speed_mm_s={speed}",
    )
    rng = np.random.default_rng(0)
    state = scene.model.base(scene.model.sample(rng), rng)
    state = stick_slip(state, rng, M_kg=M, k_l_N_m=K_L)
    periods = state.truth["stick_slip_cycles"].periods_s[1:]
    return float(periods.std() / periods.mean())


def test_acrylic_deviates_from_the_model() -> None:
    """Acrylic's adhesion makes cycles irregular and moves the frequency off the model."""
    for speed in (30.0, 80.0):
        acrylic = build(
            "sliptack_pull",
            f"scene.model.speed_mm_s={speed}",
            "scene.model.materials=[acrylic]",
        )
        f_meas, f_model = pull_frequency(acrylic, seed=3)
        assert abs(f_meas - f_model) > 0.3 * f_model
    assert _cycle_cv("cherry", 50.0) < 1e-9
    assert _cycle_cv("acrylic", 50.0) > 0.2


def test_removing_stick_slip_removes_the_oscillation() -> None:
    """Without stick_slip the nib stream is the read-out noise alone, with no spectral peak."""
    scene = build(
        "sliptack_pull", "~scene.effects.stick_slip", "scene.model.speed_mm_s=50.0"
    )
    x = scene.run_trial(0, 0).streams["nib"]["deflection"].to_numpy()
    assert 0.01 == pytest.approx(
        float(x.std()), rel=0.1
    )  # the configured noise sigma (mm)
    bare = Scene("sliptack_pull", scene.model, {})  # no effects: the backbone alone
    assert 0.0 == float(np.abs(bare.run_trial(0, 0).streams["nib"]["deflection"]).max())


# -- sliptack_drop --------------------------------------------------------------------------------
def test_drop_acceleration_truth_follows_eq4() -> None:
    """Regressing the true acceleration on x - x0 recovers g and mu_k k_a / m_t."""
    scene = build("sliptack_drop")
    ds = scene.simulate(3, seed=4)
    truth = ds.stream("truth_motion").merge(ds.trials, on="trial_id")
    moving = truth[truth["t"] >= truth["slip_onset_s"]]
    slope, intercept = np.polyfit(
        moving["axial_deflection"] * 1e-3, moving["acceleration"], 1
    )
    assert -0.45 * 2000.0 / 0.283 == pytest.approx(slope, rel=1e-9)
    assert 9.81 == pytest.approx(intercept, rel=1e-9)
    for trial in ds:
        tm = trial.streams["truth_motion"]
        t, v = tm["t"].to_numpy(), tm["speed"].to_numpy() * 1e-3
        after = t > trial.labels["slip_onset_s"] + 0.01
        dv = np.gradient(v, t)[after][1:-1]
        np.testing.assert_allclose(
            dv, tm["acceleration"].to_numpy()[after][1:-1], atol=2e-3
        )


def test_gross_deflection_carries_the_axial_deflection() -> None:
    """gross_deflection alone makes the nib signal equal x - x0; without it the hold reads 0."""
    only = build(
        "sliptack_drop", "~scene.effects.stick_slip", "~scene.effects.white_noise"
    )
    trial = only.run_trial(0, 5)
    np.testing.assert_allclose(
        trial.streams["nib"]["deflection"],
        trial.streams["truth_motion"]["axial_deflection"],
    )
    without = build(
        "sliptack_drop", "~scene.effects.gross_deflection", "~scene.effects.white_noise"
    )
    t2 = without.run_trial(0, 5)
    hold = t2.streams["nib"]["t"] < t2.labels["release_s"]
    assert 0.0 == float(np.abs(t2.streams["nib"]["deflection"][hold]).max())


def test_drop_stick_slip_starts_at_breakaway_and_speeds_up() -> None:
    """In the drop, stick-slip starts at the breakaway and nears saturation as the object speeds up."""
    scene = build(
        "sliptack_drop", "~scene.effects.gross_deflection", "~scene.effects.white_noise"
    )
    trial = scene.run_trial(0, 6)
    nib = trial.streams["nib"]
    before = nib["t"] < trial.labels["slip_onset_s"]
    assert 0.0 == float(np.abs(nib["deflection"][before]).max())
    assert float(np.ptp(nib["deflection"][~before])) > 0.5  # mm
    rng = np.random.default_rng(0)
    state = scene.model.base(scene.model.sample(rng), rng)
    cycles = stick_slip(state, rng, M_kg=M, k_l_N_m=K_L).truth["stick_slip_cycles"]
    assert cycles.break_s[0] > state.truth["slip_onset_s"]
    stick = cycles.break_s - cycles.restick_s[:-1]
    assert stick[-1] < 0.25 * cycles.periods_s[-1]  # the stick shrinks towards zero
    f_sat = float(saturation_frequency(M, K_L))
    assert 1.0 / f_sat == pytest.approx(float(cycles.periods_s[-1]), rel=0.05)


# -- datasets from the real configs -----------------------------------------------------------------
@pytest.mark.parametrize(
    ("scene_name", "truth_channels", "labels"),
    [
        (
            "sliptack_pull",
            ["position", "speed"],
            ["slip_onset_s", "speed_mm_s", "normal_force_N"],
        ),
        (
            "sliptack_drop",
            ["position", "speed", "acceleration", "axial_deflection"],
            ["slip_onset_s", "release_s", "mean_acceleration_m_s2", "deflection_mm"],
        ),
    ],
)
def test_scene_builds_a_reproducible_dataset(
    scene_name: str, truth_channels: list[str], labels: list[str]
) -> None:
    """The real config gives nib + truth streams, the labels, the material group, seeded reproducibly."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="simulate", overrides=[f"scene={scene_name}", "n_trials=3"]
        )
    scene = build_scene(cfg.scene)
    ds = scene.simulate(3, seed=0)
    assert ["nib", "truth_motion"] == sorted(ds.streams)
    assert ["deflection"] == list(ds.streams["nib"].channels)
    assert truth_channels == list(ds.streams["truth_motion"].channels)
    assert labels == list(ds.labels)
    assert ("material",) == ds.groups
    assert "sliptack" == ds.sensor
    assert 3 == len(ds)
    again = scene.simulate(3, seed=0)
    pd.testing.assert_frame_equal(ds.trials, again.trials)
    pd.testing.assert_frame_equal(ds.stream("nib"), again.stream("nib"))
    other = scene.simulate(3, seed=1)
    assert not np.array_equal(
        ds.stream("nib")["deflection"], other.stream("nib")["deflection"]
    )


def test_pull_labels_and_truth() -> None:
    """Pull labels hold the pull start and speed; the truth stream moves at that speed after it."""
    ds = build("sliptack_pull").simulate(2, seed=0)
    for trial in ds:
        tm = trial.streams["truth_motion"]
        moving = tm["t"] >= trial.labels["slip_onset_s"]
        np.testing.assert_allclose(tm["speed"][moving], trial.labels["speed_mm_s"])
        assert 0.0 == float(tm["speed"][~moving].abs().max())
        assert 0.2 == trial.labels["slip_onset_s"]
        assert 10.0 <= trial.labels["speed_mm_s"] <= 100.0


def test_cli_simulate_writes_a_loadable_dataset(tmp_path: object) -> None:
    """`slipkit simulate scene=sliptack_pull` writes a dataset that load_dataset reads back."""
    out = f"{tmp_path}/pull"
    cli_main(
        [
            "simulate",
            "scene=sliptack_pull",
            "n_trials=2",
            "seed=3",
            f"out={out}",
            "progress=false",
            "summary=false",
        ]
    )
    ds = load_dataset(out)
    assert 2 == len(ds)
    assert {"nib", "truth_motion"} == set(ds.streams)


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"speed_mm_s": [-5.0, 10.0]}, "model.speed_mm_s"),
        ({"materials": ["oak"]}, "model.materials"),
        (
            {
                "friction": {"cherry": {"mu_s": 0.5, "mu_k": 0.9}},
                "materials": ["cherry"],
            },
            "model.friction.cherry",
        ),
        ({"pull_start_s": 5.0}, "model.pull_start_s"),
        ({"rate_hz": 0.0}, "model.rate_hz"),
    ],
)
def test_bad_pull_config_names_its_key(kwargs: dict[str, object], key: str) -> None:
    """An out-of-range config value raises SimulationError naming the config key."""
    good = {
        "friction": {"cherry": {"mu_s": 0.62, "mu_k": 0.5}},
        "materials": ["cherry"],
    }
    with pytest.raises(SimulationError, match=key.replace(".", r"\.")):
        SlipTackPull(**{**good, **kwargs})


def test_bad_drop_config_names_its_key() -> None:
    """A trial too long for the object to stay in the grip names model.duration_s."""
    friction = {"basswood": {"mu_s": 0.55, "mu_k": 0.45}}
    with pytest.raises(SimulationError, match=r"model\.duration_s"):
        SlipTackDrop(duration_s=2.0, friction=friction)
    with pytest.raises(SimulationError, match=r"model\.hold_deflection_mm"):
        SlipTackDrop(
            hold_deflection_mm=2.45, slide_deflection_mm=[0.9, 2.4], friction=friction
        )


# -- nib_harmonics (issue 14) ----------------------------------------------------------------
def test_nib_harmonics_add_a_cycle_locked_second_harmonic() -> None:
    """nib_harmonics adds ratio (2/pi) D sin(2 phi) at twice the stick-slip frequency, after the pull only."""
    fx = {"stick_slip": {"M_kg": M, "k_l_N_m": K_L}}
    model = SlipTackPull(
        speed_mm_s=30.0,
        materials=["cherry"],
        friction={"cherry": {"mu_s": CHERRY[0], "mu_k": CHERRY[1]}},
    )
    plain = Scene("p", model, fx).run_trial(0, 1)
    harm = {**fx, "nib_harmonics": {"ratio": 0.7, "phase_deg": 0.0}}
    trial = Scene("p", model, harm).run_trial(0, 1)
    t = trial.streams["nib"]["t"].to_numpy()
    x0 = plain.streams["nib"]["deflection"].to_numpy()
    extra = trial.streams["nib"]["deflection"].to_numpy() - x0
    steady = t >= 0.7
    f0 = dominant_hz(x0[steady], 1000.0)
    assert 2.0 * f0 == pytest.approx(dominant_hz(extra[steady], 1000.0), rel=0.02)
    rng = np.random.default_rng([1, 0])
    state = stick_slip(model.base(model.sample(rng), rng), rng, M_kg=M, k_l_N_m=K_L)
    cycles = state.truth["stick_slip_cycles"]
    d_mm = 1e3 * float(np.median(np.abs(cycles.break_u - cycles.centre_u)))
    assert 0.7 * 2.0 / np.pi * d_mm == pytest.approx(np.abs(extra).max(), rel=0.05)
    assert 0.0 == np.abs(extra[t < cycles.break_s[0]]).max()
    with pytest.raises(SimulationError, match="list it after 'stick_slip'"):
        Scene("p", model, {"nib_harmonics": {"ratio": 0.5}}).run_trial(0, 1)
