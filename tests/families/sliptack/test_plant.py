"""SlipTack closed loop without bundles: nib oscillator, grip plant, regrasp, sensor frame, checks."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf

from slipkit import config_dir
from slipkit.closedloop.detectors import OracleDetector
from slipkit.closedloop.plant import PlantState
from slipkit.errors import SlipkitError
from slipkit.families.sliptack.physics import ConstantSpeedMotion, cycles_constant_speed
from slipkit.families.sliptack.scenario import (
    NibOscillator,
    SlipTackPlant,
    SlipTackScenario,
    SlipTackSensor,
    check_plant,
    run_sliptack_trial,
)
from slipkit.sim.commands import build_scene
from slipkit.sim.core import Scene

PLANT: dict[str, Any] = {
    "read_s": 0.03,
    "motor_s": 0.12,
    "close_tau_s": 0.02,
    "regrasp_mm": 6.0,
    "onset_s": [0.4, 0.6],
    "post_s": 1.0,
    "drop_travel_mm": 450.0,
    "pull_travel_mm": 150.0,
    "pull_load_ratio": [1.2, 2.0],
    "nib_count": 60.0,
    "substeps": 4,
}


def _scene(name: str, **effects: Any) -> Scene:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={name}"]).scene
    GlobalHydra.instance().clear()
    OmegaConf.set_struct(cfg, False)
    for key, params in effects.items():
        cfg.effects[key] = params
    return build_scene(cfg)


@pytest.fixture(scope="module")
def scenes() -> dict[str, Scene]:
    """The two SlipTack scenes the scenario uses."""
    return {"drop": _scene("sliptack_drop"), "pull": _scene("sliptack_pull")}


def _pull_plant(**kw: Any) -> SlipTackPlant:
    args: dict[str, Any] = {
        "mode": "pull",
        "mass_kg": 0.283,
        "mu_s": 0.55,
        "mu_k": 0.45,
        "k_a_N_mm": 2.0,
        "grip_mm": 1.5,
        "open_mm": 1.5,
        "release_s": 0.1,
        "opening_tau_s": 0.02,
        "load_N": 2.4,
        "pull_speed_mm_s": 50.0,
        "regrasp_mm": 6.0,
        "close_tau_s": 0.02,
        "read_s": 0.03,
        "motor_s": 0.12,
        "travel_mm": 150.0,
        "rate_hz": 1000.0,
        "substeps": 4,
    }
    args.update(kw)
    return SlipTackPlant(**args)


def _drop_plant(**kw: Any) -> SlipTackPlant:
    return _pull_plant(
        mode="drop", grip_mm=3.0, open_mm=1.5, travel_mm=450.0, load_N=0.0, **kw
    )


def _slide_after(plant: SlipTackPlant, delay_s: float, frames: int = 1500) -> float:
    """Step the plant; declare ``delay_s`` after its onset; the slide at the end, mm."""
    for _ in range(frames):
        s = plant.state
        if not math.isnan(s.onset_s) and s.t >= s.onset_s + delay_s:
            plant.regrasp(s.t)
        plant.step()
    return plant.state.drop_mm


def test_nib_oscillator_matches_the_exact_cycles() -> None:
    """At a constant pull the per-frame oscillator gives the closed-form cycles' deflection."""
    v, fn, mu_s, mu_k, m, k = 0.05, 0.05, 0.62, 0.50, 1.4e-5, 9.45
    nib = NibOscillator(M_kg=m, k_l_N_m=k)
    t = np.arange(1, 1001) * 1e-3
    u = np.array([nib.advance(1e-3, v, fn, mu_s, mu_k) for _ in t])
    motion = ConstantSpeedMotion(v0_m_s=v, start_s=0.0, normal_force_N=fn)
    expected = cycles_constant_speed(motion, 1.0, mu_s, mu_k, m, k).evaluate(t)
    assert True == bool(np.allclose(expected, u, rtol=0, atol=1e-9))  # noqa: E712


def test_pull_slide_matches_the_closed_form() -> None:
    """A pull slides v (delay + read + motor + tau ln((x_r - x0) / (x_r - Q / (mu_k k_a)))) mm."""
    delay = 0.02
    plant = _pull_plant()
    slide = _slide_after(plant, delay)
    x_k = 2.4 / (0.45 * 2.0)
    rise = 0.02 * math.log((6.0 - 1.5) / (6.0 - x_k))
    expected = 50.0 * (delay + 0.03 + 0.12 + rise)
    # the onset, the declaration and the stop each fall on a 0.25 ms substep
    assert expected == pytest.approx(slide, abs=3 * 50.0 * 0.25e-3)


def test_a_later_detection_gives_more_slip() -> None:
    """In the drop and the pull the slide grows with the detection delay (0, 25, 50, 100 ms)."""
    delays = (0.0, 0.025, 0.05, 0.1)
    drops = [_slide_after(_drop_plant(), d) for d in delays]
    pulls = [_slide_after(_pull_plant(), d) for d in delays]
    assert (True, True) == (
        all(a < b for a, b in itertools.pairwise(drops)),
        all(a < b for a, b in itertools.pairwise(pulls)),
    )


def test_held_grip_never_slips_and_the_drop_without_regrasp_is_lost() -> None:
    """The drop holds before the release; with no regrasp the object slides past the travel."""
    plant = _drop_plant()
    for _ in range(99):
        plant.step()
    held = (plant.state.drop_mm, plant.state.sliding)
    for _ in range(1500):
        plant.step()
    assert ((0.0, False), True) == (held, plant.state.dropped)


def test_oracle_trial_is_arrested_and_reproducible(scenes: dict[str, Scene]) -> None:
    """With the oracle every condition's object is caught; the same draw gives the same slide."""
    outs = [
        run_sliptack_trial(
            scenes,
            OracleDetector(),
            PLANT,
            seed=0,
            condition_index=j,
            trial=0,
            condition=c,
        )
        for j, c in enumerate((10.0, 100.0, 0.0))
    ]
    again = run_sliptack_trial(
        scenes,
        OracleDetector(),
        PLANT,
        seed=0,
        condition_index=2,
        trial=0,
        condition=0.0,
    )
    assert ([False, False, False], outs[2].slip_mm) == (
        [o.dropped for o in outs],
        again.slip_mm,
    )


def test_sensor_is_still_before_the_onset_and_oscillates_while_slipping(
    scenes: dict[str, Scene],
) -> None:
    """Without noise the nib signal is the grip's deflection while stuck and swings while sliding."""
    scene = _scene("sliptack_pull", white_noise={"target": "nib", "sigma": 0.0})
    row = scene.model.friction["cherry"]
    sensor = SlipTackSensor(scene, row, np.random.default_rng(0), nib_count=60.0)

    def state(t: float, sliding: bool) -> PlantState:
        return PlantState(
            t=t,
            indentation_mm=1.5,
            arm_mm_s=0.0,
            normal_N=3.0,
            speed_mm_s=50.0 if sliding else 0.0,
            sliding=sliding,
        )

    still = [float(sensor.frame(state(i * 1e-3, False))[0]) for i in range(50)]
    moving = [float(sensor.frame(state(0.05 + i * 1e-3, True))[0]) for i in range(300)]
    assert ([0.0] * 50, True) == (still, max(moving) - min(moving) > 0.3)


def test_effect_without_a_frame_form_is_refused() -> None:
    """A scene listing nib_harmonics (needs the next breakaway) is refused, naming the effect."""
    scene = _scene("sliptack_drop_hard")
    with pytest.raises(
        SlipkitError, match=r"sliptack_drop_hard.yaml effects \['nib_harmonics'\]"
    ):
        SlipTackSensor(
            scene,
            scene.model.friction["basswood"],
            np.random.default_rng(0),
            nib_count=60.0,
        )


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("motor_s", -0.1, "closedloop.plant.motor_s"),
        ("regrasp_mm", 0.0, "closedloop.plant.regrasp_mm"),
        ("pull_load_ratio", [0.8, 1.5], "closedloop.plant.pull_load_ratio"),
        ("onset_s", [0.6, 0.4], "closedloop.plant.onset_s"),
        ("substeps", 0, "closedloop.plant.substeps"),
    ],
)
def test_bad_plant_parameter_is_refused(key: str, value: Any, match: str) -> None:
    """A plant parameter out of range is a SlipkitError naming closedloop.plant.<key>."""
    with pytest.raises(SlipkitError, match=match):
        check_plant({**PLANT, key: value})


@pytest.mark.parametrize(
    ("pull_speeds", "drop", "expected"),
    [
        ({"lo": 10.0, "hi": 100.0, "n": 3}, True, [10.0, 31.6, 100.0, 0.0]),
        ({"lo": 10.0, "hi": 100.0, "n": 0}, True, [0.0]),
        ({"lo": 50.0, "hi": 50.0, "n": 1}, False, [50.0]),
    ],
)
def test_conditions_are_the_pull_speeds_then_the_drop(
    pull_speeds: dict[str, Any], drop: bool, expected: list[float]
) -> None:
    """The grid is the log-spaced pull speeds (mm/s), then 0 for the drop when enabled."""
    scen = OmegaConf.create({"pull_speeds": pull_speeds, "drop": drop})
    assert expected == SlipTackScenario().conditions(scen)


def test_no_condition_is_refused() -> None:
    """No pull speed and no drop is a SlipkitError naming both options."""
    scen = OmegaConf.create(
        {"pull_speeds": {"lo": 10.0, "hi": 100.0, "n": 0}, "drop": False}
    )
    with pytest.raises(
        SlipkitError, match=r"pull_speeds\.n=0 and closedloop\.drop=false"
    ):
        SlipTackScenario().conditions(scen)
