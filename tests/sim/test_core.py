"""The simulator evaluates exactly the effects a scene names, in order, reproducibly."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit import config_dir
from slipkit.data import LabelSpec, StreamSpec
from slipkit.sim import (
    EFFECTS,
    Scene,
    SceneState,
    SimulationError,
    phase_times,
    sample_times,
)
from slipkit.sim.commands import build_scene
from slipkit.sim.core import EFFECT_DRAWS, draw_effect_params, effect_name

#: Effects added for issue 14 (hard variants); the spy test checks they exist too.
NEW_EFFECTS = {
    "mindlin_creep",
    "missing_pin_frames",
    "fsr_polarity",
    "fsr_impulse_disturbance",
    "channel_offset",
    "nib_harmonics",
}


class Ramp:
    """A minimal scene model: one channel rising at `slope` per second for 1 s at 100 Hz."""

    sensor = "test"
    groups: tuple[str, ...] = ("object",)

    def __init__(self, *, slope: float = 1.0) -> None:
        self.slope = slope

    def streams(self) -> dict[str, StreamSpec]:
        return {"sig": StreamSpec("sig", ("v",), {"v": "V"}, rate_hz=100.0)}

    def labels(self) -> dict[str, LabelSpec]:
        return {"slip_onset_s": LabelSpec("slip_onset_s", unit="s")}

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        return {"object": str(rng.choice(["a", "b"]))}

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        t = sample_times(1.0, 100.0)
        return SceneState(
            time={"sig": t},
            signals={"sig": self.slope * t},
            truth={"slip_onset_s": 0.5, **params},
        )

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        streams = {
            "sig": pd.DataFrame({"t": state.time["sig"], "v": state.signals["sig"]})
        }
        return (
            streams,
            {"slip_onset_s": state.truth["slip_onset_s"]},
            {"object": state.truth["object"]},
        )


def test_unnamed_effects_are_never_called(monkeypatch: pytest.MonkeyPatch) -> None:
    """Only the effects listed in the scene run; every other registered effect is untouched."""
    called: list[str] = []
    for name in list(EFFECTS):
        real = EFFECTS[name]

        def spy(
            state: SceneState,
            rng: np.random.Generator,
            _name: str = name,
            _real: Any = real,
            **kw: Any,
        ) -> SceneState:
            called.append(_name)
            return _real(state, rng, **kw)

        monkeypatch.setitem(EFFECTS._entries, name, spy)
    scene = Scene(
        "ramp", Ramp(), {"white_noise": {"target": "sig", "sigma": [0.1, 0.2]}}
    )
    scene.simulate(3, seed=0)
    assert NEW_EFFECTS == NEW_EFFECTS & set(EFFECTS)
    assert ["white_noise"] * 3 == called


VARIANTS = sorted(
    p.stem
    for p in (config_dir() / "scene").glob("*.yaml")
    if "defaults" in p.read_text()
)


@pytest.mark.parametrize("name", VARIANTS)
def test_variants_call_exactly_their_listed_effects_in_order(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A variant scene with drawn ranges calls its listed effects once each, in `order`, no other."""
    called: list[str] = []
    for effect in list(EFFECTS):
        real = EFFECTS[effect]

        def spy(
            state: SceneState,
            rng: np.random.Generator,
            _name: str = effect,
            _real: Any = real,
            **kw: Any,
        ) -> SceneState:
            called.append(_name)
            return _real(state, rng, **kw)

        monkeypatch.setitem(EFFECTS._entries, effect, spy)
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={name}"])
    scene = build_scene(cfg.scene)
    scene.run_trial(0, seed=0)
    assert [effect_name(k) for k in scene.effect_keys()] == called


def test_effects_run_in_the_listed_order() -> None:
    """Quantising then adding noise leaves off-grid values; the reverse order does not."""
    q = {"target": "sig", "bits": 4, "full_scale": (0.0, 1.5)}
    n = {"target": "sig", "sigma": 0.01}
    a = Scene("ramp", Ramp(), {"quantisation": q, "white_noise": n}).simulate(1, seed=0)
    b = Scene("ramp", Ramp(), {"white_noise": n, "quantisation": q}).simulate(1, seed=0)
    lsb = 1.5 / 15
    on_grid = lambda v: np.allclose(np.round(v / lsb) * lsb, v)  # noqa: E731
    assert not on_grid(a.stream("sig")["v"].to_numpy())
    assert on_grid(b.stream("sig")["v"].to_numpy())


def test_removing_an_effect_removes_its_signature() -> None:
    """Without white_noise the ramp is exact; with it, residuals have the configured sigma."""
    clean = Scene("ramp", Ramp(), {}).simulate(1, seed=0).stream("sig")
    noisy = (
        Scene("ramp", Ramp(), {"white_noise": {"target": "sig", "sigma": 0.2}})
        .simulate(1, seed=0)
        .stream("sig")
    )
    np.testing.assert_array_equal(clean["t"].to_numpy(), clean["v"].to_numpy())
    assert pytest.approx(0.2, rel=0.25) == float(np.std(noisy["v"] - noisy["t"]))


def test_same_seed_same_trials_and_trial_independent_of_count() -> None:
    """Trial i depends only on (seed, i): a 2-trial run equals the first two of a 5-trial run."""
    scene = Scene(
        "ramp",
        Ramp(),
        {
            "white_noise": {"target": "sig", "sigma": 0.1},
            "dropped_frames": {"stream": "sig", "probability": 0.1},
        },
    )
    short, long_ = scene.simulate(2, seed=7), scene.simulate(5, seed=7)
    assert short.fingerprint() == long_.subset(short.trial_ids).fingerprint() or (
        short.stream("sig").equals(long_.subset(short.trial_ids).stream("sig"))
    )
    assert not scene.simulate(2, seed=8).stream("sig").equals(short.stream("sig"))


def test_dropped_frames_and_jitter_keep_time_and_signal_in_step() -> None:
    """Dropping frames leaves gaps but keeps rows aligned; jitter keeps time sorted."""
    ds = Scene(
        "ramp",
        Ramp(),
        {
            "dropped_frames": {"stream": "sig", "probability": 0.3},
            "timestamp_jitter": {"stream": "sig", "sigma_s": 1e-4},
        },
    ).simulate(1, seed=1)
    table = ds.stream("sig")
    assert 40 < len(table) < 90
    assert (np.diff(table["t"].to_numpy()) >= 0).all()
    np.testing.assert_allclose(table["t"].to_numpy(), table["v"].to_numpy(), atol=1e-3)


def test_unknown_effect_is_named() -> None:
    """A scene naming an effect that does not exist fails before simulating, naming it."""
    with pytest.raises(SimulationError, match=r"unknown effects \['tachyons'\]"):
        Scene("ramp", Ramp(), {"tachyons": {}})


def test_effect_on_missing_signal_is_named() -> None:
    """An effect pointed at a signal the scene does not produce names both."""
    with pytest.raises(SimulationError, match="'white_noise' acts on signal 'nope'"):
        Scene(
            "ramp", Ramp(), {"white_noise": {"target": "nope", "sigma": 1.0}}
        ).simulate(1)


def test_phase_and_sample_times() -> None:
    """Phases follow each other; sample times are k / rate."""
    assert {"a": (0.0, 0.5), "b": (0.5, 2.0)} == phase_times({"a": 0.5, "b": 1.5})
    np.testing.assert_allclose([0.0, 0.25, 0.5, 0.75], sample_times(1.0, 4.0))
    with pytest.raises(SimulationError, match="negative duration"):
        phase_times({"a": -1.0})


def test_an_effect_can_run_twice_under_suffixed_keys() -> None:
    """`white_noise@a` and `white_noise@b` both run: noise adds in quadrature."""
    effects = {
        "white_noise@first": {"target": "sig", "sigma": 0.3},
        "white_noise@second": {"target": "sig", "sigma": 0.4},
    }
    table = Scene("ramp", Ramp(), effects).simulate(4, seed=0).stream("sig")
    assert pytest.approx(0.5, rel=0.15) == float(np.std(table["v"] - table["t"]))


# -- per-trial draws of effect parameters ----------------------------------------------


def test_a_range_is_drawn_per_trial_and_recorded_in_the_metadata() -> None:
    """`sigma: [lo, hi]` gives each trial its own noise level, inside the range, in its metadata."""
    scene = Scene(
        "ramp", Ramp(), {"white_noise": {"target": "sig", "sigma": [0.05, 0.5]}}
    )
    ds = scene.simulate(6, seed=0)
    drawn = ds.trials["white_noise.sigma"].to_numpy()
    assert (drawn >= 0.05).all()
    assert (drawn <= 0.5).all()
    assert 6 == len(np.unique(drawn))
    for trial, sigma in zip(ds, drawn, strict=True):
        table = trial.streams["sig"]
        measured = float(np.std(table["v"] - table["t"]))
        assert pytest.approx(sigma, rel=0.3) == measured


def test_scalars_draw_nothing_and_fixed_ranges_equal_scalars() -> None:
    """A scalar parameter consumes no random numbers: `[v, v]` gives the scalar's exact signal."""
    fixed = {"white_noise": {"target": "sig", "sigma": 0.1}}
    same = {"white_noise": {"target": "sig", "sigma": [0.1, 0.1]}}
    a = Scene("ramp", Ramp(), fixed).simulate(3, seed=2)
    b = Scene("ramp", Ramp(), same).simulate(3, seed=2)
    pd.testing.assert_frame_equal(a.stream("sig"), b.stream("sig"))
    assert "white_noise.sigma" not in a.trials.columns
    assert [0.1, 0.1, 0.1] == b.trials["white_noise.sigma"].tolist()
    kwargs, drawn = draw_effect_params(
        "white_noise", {"sigma": 0.3}, rng := np.random.default_rng(0)
    )
    assert ({"sigma": 0.3}, {}) == (kwargs, drawn)
    assert np.random.default_rng(0).random() == rng.random()


def test_log_uniform_and_uniform_draws_have_their_medians() -> None:
    """Log-uniform draws centre on the geometric mean, uniform ones on the arithmetic mean."""
    rng = np.random.default_rng(1)
    log = [
        draw_effect_params("white_noise", {"sigma": [1e-3, 1e-1]}, rng)[0]["sigma"]
        for _ in range(2000)
    ]
    uni = [
        draw_effect_params("drift", {"rate_per_s": [0.0, 2.0]}, rng)[0]["rate_per_s"]
        for _ in range(2000)
    ]
    assert "log" == EFFECT_DRAWS["white_noise"]["sigma"]
    assert pytest.approx(1e-2, rel=0.15) == float(np.median(log))
    assert pytest.approx(1.0, rel=0.1) == float(np.median(uni))


def test_choice_draws_each_option_and_undeclared_lists_pass_through() -> None:
    """A choice list yields its options; a pair the effect does not declare (full_scale) is kept."""
    rng = np.random.default_rng(3)
    picks = {
        draw_effect_params("fsr_polarity", {"polarity": ["falling", "rising"]}, rng)[0][
            "polarity"
        ]
        for _ in range(50)
    }
    assert {"falling", "rising"} == picks
    kwargs, drawn = draw_effect_params(
        "quantisation@x", {"bits": 4, "full_scale": [0.0, 1.5]}, rng
    )
    assert ({"bits": 4, "full_scale": [0.0, 1.5]}, {}) == (kwargs, drawn)


@settings(max_examples=60, deadline=None)
@given(
    lo=st.floats(1e-6, 1e3),
    span=st.floats(0.0, 1e3),
    kind=st.sampled_from(["white_noise", "drift"]),
    seed=st.integers(0, 2**32 - 1),
)
def test_draws_stay_inside_their_range(
    lo: float, span: float, kind: str, seed: int
) -> None:
    """Any finite [lo, hi] (log or uniform) draws a value in [lo, hi], recorded under key.param."""
    param = "sigma" if kind == "white_noise" else "rate_per_s"
    hi = lo + span
    kwargs, drawn = draw_effect_params(
        kind, {param: [lo, hi]}, np.random.default_rng(seed)
    )
    assert lo * (1 - 1e-12) <= kwargs[param] <= hi * (1 + 1e-12)
    assert {f"{kind}.{param}": kwargs[param]} == drawn


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ([0.5, 0.1], r"scene\.effects\.white_noise@a\.sigma: expected finite lo <= hi"),
        (
            [0.0, 0.1],
            r"scene\.effects\.white_noise@a\.sigma: a log-uniform range needs lo > 0",
        ),
        (
            [0.1, "x"],
            r"scene\.effects\.white_noise@a\.sigma: expected a number or \[lo, hi\]",
        ),
        (
            [0.1, 0.2, 0.3],
            r"scene\.effects\.white_noise@a\.sigma: expected a number or \[lo, hi\]",
        ),
    ],
)
def test_bad_ranges_name_the_field(value: list, match: str) -> None:
    """A range that cannot be drawn raises a SimulationError naming scene.effects.<key>.<param>."""
    scene = Scene("ramp", Ramp(), {"white_noise@a": {"target": "sig", "sigma": value}})
    with pytest.raises(SimulationError, match=match):
        scene.simulate(1, seed=0)


def test_order_sets_the_evaluation_order_and_must_list_every_effect() -> None:
    """`order` runs effects in its order, refuses a missing or repeated key, and skips keys of removed effects."""
    effects = {
        "quantisation": {"target": "sig", "bits": 4, "full_scale": (0.0, 1.5)},
        "white_noise": {"target": "sig", "sigma": 0.01},
    }
    v = (
        Scene("ramp", Ramp(), effects, order=["white_noise", "quantisation"])
        .simulate(1, seed=0)
        .stream("sig")["v"]
        .to_numpy()
    )
    lsb = 1.5 / 15
    np.testing.assert_allclose(np.round(v / lsb) * lsb, v)
    with pytest.raises(
        SimulationError, match=r"scene.order must list each key.*\['quantisation'\]"
    ):
        Scene("ramp", Ramp(), effects, order=["white_noise"])
    with pytest.raises(SimulationError, match=r"repeated \['white_noise'\]"):
        Scene(
            "ramp",
            Ramp(),
            effects,
            order=["white_noise", "quantisation", "white_noise"],
        )
    removed = Scene("ramp", Ramp(), effects, order=["gone", *effects])
    assert tuple(effects) == removed.effect_keys()
