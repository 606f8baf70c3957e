"""slipkit closedloop scenario=fsr: the prosthetic hold with knocks and a load increase, end to end."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from slipkit import config_dir
from slipkit.closedloop.commands import closedloop_main, load_scenario, scenario_of
from slipkit.closedloop.detectors import Detector, NoDetector
from slipkit.closedloop.plant import PlantState
from slipkit.sim.commands import build_scene


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> pd.DataFrame:  # results.csv
    """One small FSR run: the paper's detector (8 training trials), 1 seed, 1 trial per condition."""
    out = tmp_path_factory.mktemp("fsr") / "cl"
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="closedloop",
            overrides=[
                "closedloop=fsr",
                "demo=true",
                "seeds=[0]",
                "trials_per_speed=1",
                "closedloop.demo.detectors=[fsr_paper]",
                f"out={out}",
            ],
        )
        closedloop_main(cfg)
    yield pd.read_csv(out / "results.csv")
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()


def test_oracle_bounds_from_below_and_no_detector_from_above(
    small: pd.DataFrame,
) -> None:
    """On the trials a detector raised no false alarm, the oracle slides and drops least, no detector drops most.

    (A false alarm's grip step before the slip can shorten the later slide, so
    those trials are left out; a drop counts the whole travel.)
    """
    clean = small[~small["false_alarm"]]
    bounded = []
    for det, g in clean.groupby("detector"):
        if det in ("oracle", "none"):
            continue
        keys = ["seed", "condition_index", "trial"]
        pair = g.merge(
            small[small["detector"] == "oracle"], on=keys, suffixes=("", "_o")
        )
        none = g.merge(small[small["detector"] == "none"], on=keys, suffixes=("", "_n"))
        bounded.append(
            bool((pair["slip_mm_o"] <= pair["slip_mm"] + 1e-9).all())
            and bool((pair["dropped_o"] <= pair["dropped"]).all())
            and bool((none["dropped_n"] >= none["dropped"]).all())
        )
    assert (True, True) == (len(bounded) > 0, all(bounded))


class _DeclareAt(Detector):
    """Declares slip on the first frame at or after ``t_s`` (a false alarm during the hold)."""

    def __init__(self, t_s: float) -> None:
        self.name = "declare_at"
        self.t_s = t_s

    def decide(self, state: PlantState, frame) -> bool:  # type: ignore[no-untyped-def]
        del frame
        return abs(state.t - self.t_s) < 0.25e-3


def test_false_alarm_raises_grip_force() -> None:
    """A declaration during the hold steps the grip up: extra force (N) and impulse (N s) above zero."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="closedloop", overrides=["closedloop=fsr"])
        scen = load_scenario(cfg)
        scene = build_scene(
            compose("train", [f"scene={scen.scene}", *list(scen.scene_overrides)]).scene
        )
    scenario = scenario_of(scen)
    plant = OmegaConf.to_container(scen.plant, resolve=True)
    kw = {"seed": 0, "condition_index": 0, "trial": 0, "condition": 0.25}
    base = scenario.run_trial(scene, NoDetector(), plant, **kw)
    alarm = scenario.run_trial(scene, _DeclareAt(0.4), plant, **kw)
    step = float(plant["step_frac"])
    assert (False, True, True, True) == (
        base.false_alarm,
        alarm.false_alarm,
        math.isclose(alarm.declared_s, 0.4, abs_tol=1e-3),
        bool(alarm.extra_force_N > 0.5 * step * 1.0 and alarm.extra_impulse_Ns > 0),
    )


def test_sensor_voltage_rises_when_the_grip_falls() -> None:
    """The FSR frame follows the paper's falling divider: less grip, higher voltage (V)."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="closedloop", overrides=["closedloop=fsr"])
        scen = load_scenario(cfg)
        scene_cfg = compose("train", [f"scene={scen.scene}"]).scene
    OmegaConf.set_struct(scene_cfg, False)
    scene_cfg.effects = {}  # no noise, knocks or slip events: the calibration alone
    from slipkit.families.fsr.scenario import FSRSensor

    sensor = FSRSensor(
        build_scene(scene_cfg),
        np.random.default_rng(0),
        t=np.arange(100) / 2000.0,
        hold_s=(0.0, 0.05),
        hold_N=2.0,
        pass_mm=12.7,
    )
    volts = [
        float(
            sensor.frame(PlantState(t=0.01, indentation_mm=0, arm_mm_s=0, normal_N=f))[
                0
            ]
        )
        for f in (0.0, 1.0, 3.0)
    ]
    assert (4.5, True) == (round(volts[0], 3), volts[0] > volts[1] > volts[2])


@pytest.fixture(scope="module")
def onset(tmp_path_factory: pytest.TempPathFactory) -> pd.DataFrame:  # results.csv
    """The onset detector in the loop: 8 training trials, 1 seed, 2 trials per condition."""
    out = tmp_path_factory.mktemp("fsr_onset") / "cl"
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="closedloop",
            overrides=[
                "closedloop=fsr",
                "demo=true",
                "seeds=[0]",
                "closedloop.demo.detectors=[fsr_onset]",
                "closedloop.demo.oracle_delays_ms=[]",
                f"out={out}",
            ],
        )
        closedloop_main(cfg)
    yield pd.read_csv(out / "results.csv")
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()


def test_onset_detector_is_fast_and_knock_proof(onset: pd.DataFrame) -> None:
    """The exported onset bundle: no false alarm through the knocks, every slide declared
    2 ms after its onset, every object caught."""
    det = onset[onset["detector"] == "fsr_onset"]
    assert (6, 0, [2.0] * 6, 0) == (
        len(det),
        int(det["false_alarm"].sum()),
        det["delay_ms"].round(3).tolist(),
        int(det["dropped"].sum()),
    )
