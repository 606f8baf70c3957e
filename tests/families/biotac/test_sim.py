"""BioTac scenes (Su et al. 2015): geometry, effect signatures, configs and the CLI."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal as sps
from sklearn.linear_model import LinearRegression

from slipkit import config_dir
from slipkit.data import load_dataset
from slipkit.families.biotac.physics import (
    CORE_RADIUS_MM,
    CYLINDER_LENGTH_MM,
    ELECTRODE_NAMES,
    ELECTRODE_NORMALS,
    ELECTRODE_POSITIONS_MM,
    MIRROR,
    cone_directions,
    linear_drive_matrix,
    neighbour_kernel,
    surface_point,
    weighted_normals_features,
    weighted_normals_force,
    weighted_normals_scales,
)
from slipkit.families.biotac.scene import BioTacForceProbe, BioTacLiftSlip
from slipkit.sim import EFFECTS, Scene, SceneState, SimulationError
from slipkit.sim.commands import build_scene

BASE = 2000.0
LEFT = np.arange(6)  # e1..e6, mirrored by e11..e16
PAC_BAND = (60.0, 700.0)


def scene_from_config(name: str, *overrides: str) -> Scene:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="simulate",
            overrides=[f"scene={name}", "n_trials=3", *overrides],
        )
    return build_scene(cfg.scene)


def without(scene: Scene, *names: str) -> Scene:
    """The same scene with the named effects removed from its list."""
    kept = {k: v for k, v in scene.effects.items() if k not in names}
    return Scene(scene.name, scene.model, kept)


def electrode_state(delta: np.ndarray, **truth: Any) -> SceneState:
    """A bare electrode stream at 300 Hz holding ``BASE + delta``."""
    delta = np.atleast_2d(delta)
    t = np.arange(len(delta)) / 300.0
    return SceneState(
        time={"electrodes": t},
        signals={"electrodes": BASE + delta},
        truth={"electrode_baseline": np.full(19, BASE), **truth},
    )


def band_level(
    pac: pd.DataFrame, start: float, stop: float, rate: float = 2200.0
) -> float:
    """Mean rectified 60-700 Hz AC pressure between ``start`` and ``stop`` (s)."""
    sos = sps.butter(4, PAC_BAND, btype="bandpass", fs=rate, output="sos")
    x = pac["pac"].to_numpy()
    y = np.abs(sps.sosfiltfilt(sos, x - x.mean()))
    t = pac["t"].to_numpy()
    return float(y[(t >= start) & (t < stop)].mean())


def lift_model(**kw: Any) -> BioTacLiftSlip:
    """A lift scene with the contact on the pad's centre line and the load along -x."""
    args: dict[str, Any] = {"contact_phi_deg": 0.0, "load_direction_deg": 0.0}
    return BioTacLiftSlip(**{**args, **kw})


# -- geometry and the weighted-normals relation ----------------------------------------


def test_electrodes_lie_on_the_core_with_unit_outward_normals() -> None:
    """19 electrodes sit on the cylinder-plus-hemisphere core, normals unit and outward."""
    p, n = ELECTRODE_POSITIONS_MM, ELECTRODE_NORMALS
    assert ELECTRODE_NAMES == tuple(f"e{i}" for i in range(1, 20))
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), np.ones(19))
    centre = np.zeros_like(p)
    centre[:, 0] = np.minimum(p[:, 0], CYLINDER_LENGTH_MM)
    np.testing.assert_allclose(p, centre + CORE_RADIUS_MM * n)
    assert np.all(n[:, 2] > 0.0)  # all on the pad side or tip, none on the nail side


def test_mirror_map_reflects_electrodes_across_the_xz_plane() -> None:
    """MIRROR maps each electrode to its image under y -> -y."""
    flip = np.array([1.0, -1.0, 1.0])
    np.testing.assert_allclose(
        ELECTRODE_POSITIONS_MM[MIRROR] * flip, ELECTRODE_POSITIONS_MM
    )
    np.testing.assert_array_equal(np.arange(19), MIRROR[MIRROR])


@settings(max_examples=40, deadline=None)
@given(
    gain=st.tuples(*[st.floats(1.0, 200.0)] * 3),
    force=st.lists(st.tuples(*[st.floats(-20.0, 20.0)] * 3), min_size=1, max_size=5),
)
def test_linear_drive_obeys_weighted_normals_exactly(
    gain: tuple[float, float, float], force: list[tuple[float, float, float]]
) -> None:
    """For E = A F the weighted-normals sum with S = 1 / diag(N^T A) returns F exactly."""
    a = linear_drive_matrix(gain)
    f = np.array(force)
    np.testing.assert_allclose(
        weighted_normals_force(f @ a.T, weighted_normals_scales(a)), f, atol=1e-9
    )
    np.testing.assert_allclose(np.abs(a).max(axis=0), gain)


def test_cone_directions_stay_within_the_cone() -> None:
    """Directions drawn in a cone are unit vectors within its half-angle of the axis."""
    rng = np.random.default_rng(0)
    _, axis = surface_point(rng.uniform(0, 24, 500), rng.uniform(-1, 1, 500))
    d = cone_directions(axis, np.deg2rad(30.0), rng.random(500), rng.random(500))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), np.ones(500))
    assert np.all(np.einsum("ij,ij->i", d, axis) >= np.cos(np.deg2rad(30.0)) - 1e-12)


# -- electrode non-linearity effects ----------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(
    delta=st.lists(
        st.floats(-5e3, 5e3).map(lambda v: round(v, 3)), min_size=19, max_size=19
    ),
    sat=st.floats(10.0, 1000.0),
)
def test_saturation_bounds_and_preserves_order(delta: list[float], sat: float) -> None:
    """electrode_saturation keeps |E| within s, keeps the sign and never reverses order."""
    e = np.array(delta)
    out = (
        EFFECTS["electrode_saturation"](
            electrode_state(e), None, saturation_counts=sat
        ).signals["electrodes"][0]
        - BASE
    )
    assert np.all(
        np.abs(out) <= sat + 1e-9 * BASE
    )  # counts are absolute: allow round-off
    np.testing.assert_array_equal(np.sign(e), np.sign(out))
    order = np.argsort(e)
    assert np.all(np.diff(out[order]) >= 0.0)


def test_saturation_is_linear_for_small_and_flat_for_large_changes() -> None:
    """A 1-count change passes unchanged; a 10x saturation change reads the saturation."""
    e = np.zeros((2, 19))
    e[0, 0], e[1, 0] = 1.0, 3000.0
    out = (
        EFFECTS["electrode_saturation"](
            electrode_state(e), None, saturation_counts=300.0
        ).signals["electrodes"][:, 0]
        - BASE
    )
    assert pytest.approx(1.0, rel=1e-5) == out[0]
    assert pytest.approx(300.0, rel=1e-6) == out[1]


def test_coupling_lowers_neighbours_of_a_compressed_electrode_only() -> None:
    """A compressed e18 lowers the others by strength K_ij E_18; a relaxed one does not."""
    e = np.zeros((2, 19))
    e[0, 17], e[1, 17] = 100.0, -100.0
    out = (
        EFFECTS["electrode_coupling"](
            electrode_state(e), None, strength=0.2, length_mm=5.0
        ).signals["electrodes"]
        - BASE
    )
    expected = -0.2 * neighbour_kernel(5.0)[:, 17] * 100.0
    expected[17] = 100.0
    np.testing.assert_allclose(out[0], expected)
    np.testing.assert_allclose(out[1], e[1])
    assert out[0, 16] < out[0, 9] < 0.0  # e17 (4.5 mm away) loses more than e10 (tip)


def test_contact_locality_makes_the_same_force_read_differently_by_place() -> None:
    """One force at two contact points gives two weighted-normal sums; depth 0 gives one."""
    a = linear_drive_matrix(60.0)
    e = np.tile(np.array([0.0, 0.0, 5.0]) @ a.T, (2, 1))
    pad, _ = surface_point(4.0, 0.0)
    tip, _ = surface_point(20.0, 0.0)
    state = electrode_state(
        e,
        contact_start_s=np.array([0.0, 1.0 / 300.0]),
        contact_point_mm=np.stack([pad, tip]),
    )
    fx = EFFECTS["contact_locality"]
    local = weighted_normals_features(
        fx(state, None, width_mm=8.0, depth=0.6).signals["electrodes"] - BASE
    )
    flat = weighted_normals_features(
        fx(state, None, width_mm=8.0, depth=0.0).signals["electrodes"] - BASE
    )
    assert abs(local[0, 2] - local[1, 2]) > 0.1 * abs(local[0, 2])
    np.testing.assert_allclose(flat[0], flat[1])


def _fit_residuals(ds: Any) -> np.ndarray:
    """Residuals (N, one column per axis) of per-axis least squares of F_k on
    sum_i E_i N_k,i with intercept: the weighted-normals method of Su et al. 2015."""
    e = ds.tables["electrodes"][list(ELECTRODE_NAMES)].to_numpy() - BASE
    f = ds.tables["truth_force"][["fx", "fy", "fz"]].to_numpy()
    x = weighted_normals_features(e)
    return np.column_stack(
        [
            f[:, k] - LinearRegression().fit(x[:, [k]], f[:, k]).predict(x[:, [k]])
            for k in range(3)
        ]
    )


def _rmse(res: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(res**2, axis=0))


def _tip_minus_pad_offset(ds: Any, res: np.ndarray) -> np.ndarray:
    """Mean residual (N) of loaded (> 3 N) presses on the tip minus those on the pad."""
    tip = ds.tables["truth_contact"]["cx"].to_numpy() > CYLINDER_LENGTH_MM
    f = ds.tables["truth_force"][["fx", "fy", "fz"]].to_numpy()
    loaded = np.linalg.norm(f, axis=1) > 3.0
    return res[loaded & tip].mean(axis=0) - res[loaded & ~tip].mean(axis=0)


def test_force_probe_nonlinearity_defeats_the_weighted_normals_fit() -> None:
    """Locality, coupling and saturation leave residuals >= 5x the noise-only ones and
    offsets that differ between tip and pad presses; without them the fit is near exact."""
    scene = scene_from_config("biotac_force_probe", "scene.model.duration_s=20")
    nonlinear = ("contact_locality", "electrode_coupling", "electrode_saturation")
    full = scene.simulate(2, seed=0)
    bare = Scene(scene.name, scene.model, {}).simulate(2, seed=0)
    full_res, bare_res = _fit_residuals(full), _fit_residuals(bare)
    noisy_rmse = _rmse(_fit_residuals(without(scene, *nonlinear).simulate(2, seed=0)))
    np.testing.assert_array_less(_rmse(bare_res), 1e-9)
    np.testing.assert_array_less(np.abs(_tip_minus_pad_offset(bare, bare_res)), 1e-9)
    np.testing.assert_array_less(noisy_rmse, 0.05)
    assert np.all(_rmse(full_res)[[0, 2]] > 5.0 * noisy_rmse[[0, 2]])
    assert np.abs(_tip_minus_pad_offset(full, full_res)[[0, 2]]).max() > 0.15


@pytest.mark.parametrize(
    "effect", ["contact_locality", "electrode_coupling", "electrode_saturation"]
)
def test_each_nonlinear_effect_alone_breaks_the_exact_fit(effect: str) -> None:
    """Each electrode non-linearity alone leaves a residual the linear backbone does not."""
    scene = scene_from_config("biotac_force_probe", "scene.model.duration_s=10")
    alone = Scene(scene.name, scene.model, {effect: scene.effects[effect]})
    assert _rmse(_fit_residuals(alone.simulate(1, seed=0))).max() > 0.02


# -- lift and slip --------------------------------------------------------------------


def _slip_shift(model: BioTacLiftSlip, cls: str, **kw: Any) -> np.ndarray:
    """Electrode change (counts) that slip_deformation adds 0.2 s after the onset."""
    params = {**model.sample(np.random.default_rng(0)), "slip_class": cls}
    state = model.base(params, np.random.default_rng(0))
    after = EFFECTS["slip_deformation"](state, None, **kw)
    t = state.time["electrodes"]
    i = int(np.searchsorted(t, state.truth["slip_onset_s"] + 0.2))
    return after.signals["electrodes"][i] - state.signals["electrodes"][i]


SLIP_KW = {
    "gain_counts_per_mm": 150.0,
    "drag_mm": 0.5,
    "twist_deg": 8.0,
    "tau_s": 0.05,
    "width_mm": 8.0,
}


def test_linear_slip_moves_opposite_side_electrodes_together() -> None:
    """Linear slip: each side electrode and its mirror image change equally (same sign)."""
    d = _slip_shift(lift_model(), "linear", **SLIP_KW)
    assert np.all(d[LEFT] > 1.0)
    np.testing.assert_allclose(d[LEFT], d[MIRROR[LEFT]])


def test_rotational_slip_moves_opposite_side_electrodes_against_each_other() -> None:
    """Rotational slip: each side electrode and its mirror change by opposite amounts."""
    d = _slip_shift(lift_model(), "rotational", **SLIP_KW)
    assert np.all(np.abs(d[LEFT]) > 1.0)
    np.testing.assert_allclose(d[LEFT], -d[MIRROR[LEFT]])
    np.testing.assert_allclose(d[16:], np.zeros(3), atol=1e-9)  # on the load line


def test_slip_deformation_starts_at_the_true_onset() -> None:
    """The slip pattern is zero before the true onset and grows after it."""
    model = lift_model()
    params = {**model.sample(np.random.default_rng(1)), "slip_class": "rotational"}
    state = model.base(params, np.random.default_rng(1))
    d = (
        EFFECTS["slip_deformation"](state, None, **SLIP_KW).signals["electrodes"]
        - state.signals["electrodes"]
    )
    t = state.time["electrodes"]
    t0 = state.truth["slip_onset_s"]
    np.testing.assert_array_equal(d[t < t0], np.zeros_like(d[t < t0]))
    size = np.abs(d).sum(axis=1)
    assert size[np.searchsorted(t, t0 + 0.01)] < size[np.searchsorted(t, t0 + 0.1)]


def test_removing_slip_deformation_removes_the_rotational_signature() -> None:
    """Scene level: left-minus-right electrodes split in rotational slip only with the effect."""
    scene = scene_from_config(
        "biotac_lift_slip",
        "scene.model.contact_phi_deg=0.0",
        "scene.model.load_direction_deg=0.0",
        "scene.model.slip_classes=[rotational]",
    )

    def split(sc: Scene) -> float:
        tr = sc.simulate(1, seed=0).trial(f"{sc.name}-00000")
        e = tr.streams["electrodes"]
        t0 = tr.labels["slip_onset_s"]
        win = e[(e["t"] > t0 + 0.1) & (e["t"] < t0 + 0.25)][
            list(ELECTRODE_NAMES)
        ].to_numpy()
        return float(np.abs((win[:, LEFT] - win[:, MIRROR[LEFT]]).mean(axis=0)).max())

    assert split(scene) > 20.0
    assert split(without(scene, "slip_deformation")) < 2.0


def test_pac_band_power_rises_only_during_slip() -> None:
    """60-700 Hz AC pressure: > 2x the motor baseline during slip, ~1x when the effect is removed."""
    scene = scene_from_config("biotac_lift_slip")
    for sc, lo, hi in (
        (scene, 2.0, np.inf),
        (without(scene, "slip_vibration"), 0.8, 1.25),
    ):
        for tr in sc.simulate(3, seed=2):
            t0, t_end = tr.labels["slip_onset_s"], tr.labels["slip_onset_s"] + 0.2
            pac = tr.streams["pac"]
            ratio = band_level(pac, t0 + 0.01, t_end) / band_level(pac, t0 - 0.3, t0)
            assert lo < ratio < hi


def test_motor_vibration_is_a_tone_at_its_frequency_at_all_times() -> None:
    """Before slip the AC pressure peaks at the motor frequency; removed, the band is ~empty."""
    scene = scene_from_config(
        "biotac_lift_slip", "scene.effects.motor_vibration.freq_hz=230.0"
    )
    tr = scene.simulate(1, seed=0).trial("biotac_lift_slip-00000")
    pac = tr.streams["pac"]
    pre = pac[pac["t"] < tr.labels["slip_onset_s"]]["pac"].to_numpy()
    f, p = sps.welch(pre - pre.mean(), fs=2200.0, nperseg=1024)
    band = f >= PAC_BAND[0]  # above the grip-force transient of the backbone
    assert pytest.approx(230.0, abs=3.0) == f[band][np.argmax(p[band])]
    bare = (
        without(scene, "motor_vibration")
        .simulate(1, seed=0)
        .trial("biotac_lift_slip-00000")
    )
    t0 = tr.labels["slip_onset_s"]
    assert band_level(bare.streams["pac"], t0 - 0.3, t0) < 0.1 * band_level(
        pac, t0 - 0.3, t0
    )


def test_reference_onset_lags_true_onset_by_the_imu_delay() -> None:
    """reference_onset_s - slip_onset_s equals imu_delay_s (default and overridden)."""
    for overrides, delay in (((), 0.045), (("scene.model.imu_delay_s=0.02",), 0.02)):
        trials = (
            scene_from_config("biotac_lift_slip", *overrides).simulate(4, seed=0).trials
        )
        np.testing.assert_allclose(
            trials["reference_onset_s"] - trials["slip_onset_s"], delay
        )


def test_tangential_force_falls_below_minus_half_newton_per_second_after_the_imu() -> (
    None
):
    """dFt/dt < -0.5 N/s first happens after gross slip (after the IMU onset), never before."""
    scene = scene_from_config("biotac_lift_slip")
    for tr in scene.simulate(4, seed=3):
        f = tr.streams["truth_force"]
        t, ft = f["t"].to_numpy(), f["ft"].to_numpy()
        first = t[1:][np.diff(ft) / np.diff(t) < -0.5][0]
        assert tr.labels["reference_onset_s"] < first
        assert (
            pytest.approx(tr.labels["slip_onset_s"] + 0.055, abs=2.0 / 300.0) == first
        )


def test_slip_force_matches_friction_at_onset() -> None:
    """At the onset the tangential force is mu_s Fn of the drawn object."""
    model = BioTacLiftSlip()
    params = model.sample(np.random.default_rng(4))
    state = model.base(params, np.random.default_rng(4))
    f = state.signals["truth_force"]
    i = int(
        np.searchsorted(state.time["truth_force"], state.truth["slip_onset_s"] + 0.01)
    )
    mu = model.objects[params["object"]]["mu_static"]
    assert pytest.approx(mu * state.truth["grip_force_N"]) == f[i, 3]
    np.testing.assert_allclose(
        np.hypot(f[:, 3], f[:, 4]), np.linalg.norm(f[:, :3], axis=1)
    )


# -- validation --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("cls", "kwargs", "key"),
    [
        (BioTacForceProbe, {"cone_deg": 95.0}, "cone_deg"),
        (BioTacForceProbe, {"force_N": [5.0, 1.0]}, "force_N"),
        (BioTacForceProbe, {"contact_s_mm": [0.0, 40.0]}, "contact_s_mm"),
        (BioTacLiftSlip, {"incipient_s": 0.5}, "incipient_s"),
        (BioTacLiftSlip, {"slip_classes": ["sideways"]}, "slip_classes"),
        (BioTacLiftSlip, {"objects": {"cup": {"mass_kg": 0.1}}}, "objects.cup"),
        (BioTacLiftSlip, {"slip_load_fraction": 1.5}, "slip_load_fraction"),
    ],
)
def test_bad_config_values_name_their_key(
    cls: type, kwargs: dict[str, Any], key: str
) -> None:
    """An out-of-range config value raises SimulationError naming its key."""
    with pytest.raises(SimulationError, match=key):
        cls(**kwargs)


def test_electrode_effect_on_a_non_electrode_signal_is_refused() -> None:
    """electrode_saturation on the 1-D AC pressure raises SimulationError naming the signal."""
    state = BioTacLiftSlip().base(
        BioTacLiftSlip().sample(np.random.default_rng(0)), np.random.default_rng(0)
    )
    with pytest.raises(SimulationError, match="pac"):
        EFFECTS["electrode_saturation"](
            state, None, target="pac", saturation_counts=10.0
        )


# -- scenes from the real configs ------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "overrides", "streams", "labels", "groups"),
    [
        (
            "biotac_force_probe",
            ("scene.model.duration_s=5",),
            {"electrodes", "pdc", "truth_force", "truth_contact"},
            {"slip_onset_s"},
            (),
        ),
        (
            "biotac_lift_slip",
            (),
            {"electrodes", "pac", "truth_force"},
            {"slip_onset_s", "reference_onset_s", "slip_class"},
            ("object",),
        ),
    ],
)
def test_scene_from_config_is_complete_and_deterministic(
    name: str,
    overrides: tuple[str, ...],
    streams: set[str],
    labels: set[str],
    groups: tuple[str, ...],
) -> None:
    """The config builds a dataset with its streams, labels and groups; seeds reproduce."""
    scene = scene_from_config(name, *overrides)
    ds = scene.simulate(3, seed=0)
    assert "biotac" == ds.sensor
    assert streams == set(ds.tables)
    assert labels == set(ds.labels)
    assert groups == ds.groups
    assert ELECTRODE_NAMES == ds.streams["electrodes"].channels
    assert 300.0 == ds.streams["electrodes"].rate_hz
    again = scene.simulate(3, seed=0)
    other = scene.simulate(3, seed=1)
    pd.testing.assert_frame_equal(ds.trials, again.trials)
    for s in streams:
        pd.testing.assert_frame_equal(ds.tables[s], again.tables[s])
    assert not ds.tables["electrodes"].equals(other.tables["electrodes"])


def test_lift_slip_config_has_the_papers_rates_objects_and_classes() -> None:
    """Electrodes at 300 Hz, PAC at 2.2 kHz, four objects, both slip classes."""
    scene = scene_from_config("biotac_lift_slip")
    ds = scene.simulate(12, seed=0)
    assert 2200.0 == ds.streams["pac"].rate_hz
    assert 4 == len(scene.model.objects)
    assert {"linear", "rotational"} == set(ds.trials["slip_class"])
    assert ds.trials["slip_onset_s"].notna().all()


@pytest.mark.parametrize("name", ["biotac_force_probe", "biotac_lift_slip"])
def test_cli_simulate_writes_a_loadable_dataset(name: str, tmp_path: Any) -> None:
    """`slipkit simulate scene=<biotac scene>` writes a dataset that load_dataset reads."""
    from slipkit.cli import main

    out = tmp_path / name
    main(
        [
            "simulate",
            f"scene={name}",
            "n_trials=2",
            "seed=5",
            f"out={out}",
            "progress=false",
            "summary=false",
            "scene.model.duration_s=3"
            if name == "biotac_force_probe"
            else "scene.model.slip_s=0.2",
        ]
    )
    ds = load_dataset(out)
    assert 2 == len(ds)
    assert "biotac" == ds.sensor
    assert ELECTRODE_NAMES == ds.streams["electrodes"].channels


def test_channel_offset_shifts_each_electrode_by_a_constant_per_trial() -> None:
    """channel_offset adds one constant per electrode and trial, of s.d. sigma, different across trials."""
    model = BioTacForceProbe(duration_s=5.0)
    bare = Scene("b", model, {})
    shifted = Scene(
        "b", model, {"channel_offset": {"target": "electrodes", "sigma": 50.0}}
    )
    offsets = []
    for i in range(3):
        a = bare.run_trial(i, 0).streams["electrodes"].drop(columns="t").to_numpy()
        b = shifted.run_trial(i, 0).streams["electrodes"].drop(columns="t").to_numpy()
        diff = b - a
        np.testing.assert_allclose(diff, np.broadcast_to(diff[0], diff.shape))
        offsets.append(diff[0])
    assert 50.0 == pytest.approx(float(np.std(offsets)), rel=0.3)
    assert not np.allclose(offsets[0], offsets[1])


def test_pdc_rises_with_the_normal_load() -> None:
    """DC pressure = baseline + gain x (force along the contact normal)."""
    model = BioTacForceProbe(duration_s=5.0)
    state = model.base(model.sample(np.random.default_rng(0)), np.random.default_rng(0))
    f, c = state.signals["truth_force"], state.signals["truth_contact"]
    centre = np.zeros_like(c)
    centre[:, 0] = np.minimum(c[:, 0], CYLINDER_LENGTH_MM)
    normal_load = np.einsum("ij,ij->i", f, (c - centre) / CORE_RADIUS_MM)
    np.testing.assert_allclose(state.signals["pdc"], 2000.0 + 30.0 * normal_load)
    assert normal_load.max() > 1.0
