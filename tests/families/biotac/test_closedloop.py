"""slipkit closedloop scenario=biotac: lift with a load change under Fz = Ft / mu + margin, end to end."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from slipkit import config_dir
from slipkit.closedloop.commands import closedloop_main, load_scenario, scenario_of
from slipkit.closedloop.detectors import Detector, NoDetector, OracleDetector
from slipkit.closedloop.plant import PlantState
from slipkit.families.biotac.scenario import FrictionController
from slipkit.sim.commands import build_scene


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> pd.DataFrame:  # results.csv
    """One small BioTac run: the pressure detector (8 training trials), 1 seed, 1 trial per condition."""
    out = tmp_path_factory.mktemp("biotac") / "cl"
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="closedloop",
            overrides=[
                "closedloop=biotac",
                "demo=true",
                "seeds=[0]",
                "trials_per_speed=1",
                "closedloop.demo.detectors=[pressure]",
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
    """Declares slip on the frame at ``t_s`` (a false alarm while the object is held)."""

    def __init__(self, t_s: float) -> None:
        self.name = "declare_at"
        self.t_s = t_s

    def decide(self, state: PlantState, frame) -> bool:  # type: ignore[no-untyped-def]
        del frame
        return abs(state.t - self.t_s) < 0.23e-3


def _scenario():  # type: ignore[no-untyped-def]
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="closedloop", overrides=["closedloop=biotac"])
        scen = load_scenario(cfg)
        scene = build_scene(compose("train", [f"scene={scen.scene}"]).scene)
    return scenario_of(scen), scene, OmegaConf.to_container(scen.plant, resolve=True)


def test_false_alarm_during_the_hold_raises_grip_force() -> None:
    """A declaration while the lifted object is held lowers mu's estimate: extra grip (N, N s) above zero."""
    scenario, scene, plant = _scenario()
    kw = {"seed": 0, "condition_index": 2, "trial": 0, "condition": 0.2}
    hold = float(plant["approach_s"]) + float(plant["press_s"]) + float(plant["lift_s"])
    t_alarm = hold + 0.5 * float(plant["hold_s"])
    oracle = scenario.run_trial(scene, OracleDetector(), plant, **kw)
    # The oracle's slides end before the alarm (so it falls while the object is stuck).
    assert True == bool(oracle.arrest_s < t_alarm - 0.05)  # noqa: E712

    class OracleThenAlarm(_DeclareAt):
        def decide(self, state, frame):  # type: ignore[no-untyped-def]
            return state.sliding or super().decide(state, frame)

    alarm = scenario.run_trial(scene, OracleThenAlarm(t_alarm), plant, **kw)
    assert (False, True, True) == (
        oracle.false_alarm,
        alarm.false_alarm,
        bool(alarm.extra_force_N > 0 and alarm.extra_impulse_Ns > 0),
    )


def test_no_detector_drops_what_the_oracle_catches() -> None:
    """On the same draw the no-detector run drops the object that the oracle holds."""
    scenario, scene, plant = _scenario()
    kw = {"seed": 0, "condition_index": 0, "trial": 0, "condition": 0.02}
    none = scenario.run_trial(scene, NoDetector(), plant, **kw)
    oracle = scenario.run_trial(scene, OracleDetector(), plant, **kw)
    assert (True, False) == (none.dropped, oracle.dropped)


def test_friction_controller_relearns_mu_at_a_declared_slip() -> None:
    """Fz = Ft / mu (1 + margin); a declared slip sets mu = Ft / Fz (measured), so the command becomes Fz (1 + margin)."""
    ctl = FrictionController(
        mu=1.0, margin=0.2, min_N=0.5, max_N=20.0, close_s=0.0, control_hz=300.0
    )

    def state(t: float, normal: float) -> PlantState:
        return PlantState(
            t=t, indentation_mm=0.0, arm_mm_s=0.0, normal_N=normal, tangential_N=2.0
        )

    first = ctl.command(state(0.0, 2.0), False)  # 2 / 1.0 * 1.2 = 2.4 N
    second = ctl.command(state(1 / 300, 2.4), True)  # mu = 2 / 2.4: 2.4 * 1.2 N
    held = ctl.command(state(2 / 300, 2.88), False)  # mu kept: 2.88 N again
    assert (True, True, True) == (
        math.isclose(first, 2.4),
        math.isclose(second, 2.4 * 1.2),
        math.isclose(held, 2.4 * 1.2),
    )
