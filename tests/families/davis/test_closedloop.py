"""slipkit closedloop scenario=davis: press, hold and lift with incipient slip seen in the contact area."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from slipkit import config_dir
from slipkit.closedloop.commands import closedloop_main, load_scenario, scenario_of
from slipkit.closedloop.detectors import Detector, NoDetector, OracleDetector
from slipkit.closedloop.plant import PlantState
from slipkit.closedloop.scenarios import get_scenario
from slipkit.errors import SlipkitError
from slipkit.families.davis.scenario import (
    ContactModel,
    cut_for_fraction,
    frame_channels,
    kept_fraction,
)
from slipkit.families.davis.scene import DavisRelease
from slipkit.sim.commands import build_scene

#: the slow lift (s) and the fast one
SLOW, FAST = 0.5, 0.05


def _setup(*scene_overrides: str) -> tuple[Any, Any, dict[str, Any]]:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="closedloop", overrides=["closedloop=davis"])
        scen = load_scenario(cfg)
        scene = build_scene(
            compose("train", [f"scene={scen.scene}", *scene_overrides]).scene
        )
    plant = OmegaConf.to_container(scen.plant, resolve=True)
    assert isinstance(plant, dict)
    return scenario_of(scen), scene, plant


def _trial(detector: Detector, condition: float = SLOW, **plant: Any):  # type: ignore[no-untyped-def]
    scenario, scene, cfg = _setup()
    return scenario.run_trial(
        scene,
        detector,
        {**cfg, **plant},
        seed=0,
        condition_index=0,
        trial=0,
        condition=condition,
    )


def test_davis_is_a_registered_scenario() -> None:
    """scenario=davis finds the DAVIS scenario with the lift time as its condition."""
    assert "lift time (s)" == get_scenario("davis").condition_label


def test_cut_keeps_the_asked_fraction_of_the_disc() -> None:
    """The cut across the unit disc keeps the asked fraction (half at the centre line)."""
    kept = np.array([0.0, 0.25, 0.5, 0.7, 1.0])
    assert ([0.5], np.round(kept, 6).tolist()) == (
        kept_fraction(np.array([0.0])).tolist(),
        np.round(kept_fraction(cut_for_fraction(kept)), 6).tolist(),
    )


def _contact(area_loss: float = 0.2) -> ContactModel:
    model = DavisRelease()
    rng = np.random.default_rng(3)
    return ContactModel(
        patch=model.patch(model.sample(rng)), hold_N=1.0, mu_s=1.0, area_loss=area_loss
    )


def test_contact_area_shrinks_as_the_shear_grows() -> None:
    """At the hold grip the area falls from the hold's to 1 - area_loss of it as tau rises to mu_s F."""
    c = _contact(0.2)
    ratios = [c.area_ratio(1.0, tau) for tau in (0.0, 0.25, 0.5, 0.75, 1.0, 1.5)]
    assert (True, 1.0, 0.8, 0.8) == (
        bool(np.all(np.diff(ratios[:5]) < 0)),
        ratios[0],
        round(ratios[4], 12),
        round(ratios[5], 12),
    )


def test_covered_pixels_follow_the_area_and_lose_the_trailing_side() -> None:
    """Pixels the contact covers match the area law, and the sheared contact lost them on one side only."""
    c = _contact(0.3)
    p = c.patch
    gx, gy = np.meshgrid(np.arange(190.0), np.arange(180.0))
    x, y = gx.ravel(), gy.ravel()
    inside, _ = c.cover(
        np.array([1.0, 1.0, 0.5]), np.array([0.0, 1.0, 0.0]), np.zeros(3), x, y
    )
    counts = inside.sum(axis=1)
    want = [c.hold_area_px, 0.7 * c.hold_area_px, 0.5 ** (2 / 3) * c.hold_area_px]
    lost = inside[0] & ~inside[1]
    side = p.projection(x[lost], y[lost])
    assert ([True] * 3, True, True) == (
        [bool(abs(n - w) < 0.03 * w) for n, w in zip(counts, want, strict=True)],
        bool(np.all(side > 0)),
        bool(np.all(inside[1] <= inside[0])),
    )


def test_no_detector_drops_what_the_oracle_holds_without_a_slide() -> None:
    """The light grasp loses the object with no response; the oracle catches it before it slides."""
    none = _trial(NoDetector())
    oracle = _trial(OracleDetector())
    assert (True, 10.0, False, 0.0, 0.0) == (
        none.dropped,
        none.slip_mm,
        oracle.dropped,
        oracle.slip_mm,
        oracle.delay_ms,
    )


def test_slide_grows_with_the_detection_delay() -> None:
    """On the fast lift, the oracle delayed by 0, 20, 44 ms slides more with each delay."""
    slides = [
        _trial(OracleDetector(f"d{d}", delay_s=d / 1e3), FAST).slip_mm
        for d in (0, 20, 44)
    ]
    assert (True, 0.0) == (bool(slides[0] < slides[1] < slides[2]), slides[0])


class _DeclareAt(Detector):
    """Declares slip at ``t_s`` (reads no frame)."""

    def __init__(self, t_s: float) -> None:
        self.name = "declare_at"
        self.t_s = t_s

    def decide(self, state: PlantState, frame: Callable[[], np.ndarray]) -> bool:
        del frame
        return state.t >= self.t_s


def test_a_false_alarm_in_the_hold_costs_grip_and_keeps_the_object() -> None:
    """A declaration while the object is held is a false alarm: extra grip (N, N s), object kept."""
    alarm = _trial(_DeclareAt(0.8))  # press ends by 0.7 s, the lift starts after 0.9 s
    assert (True, False, True, True) == (
        alarm.false_alarm,
        alarm.dropped,
        alarm.extra_force_N > 0,
        alarm.extra_impulse_Ns > 0,
    )


class _Frames(Detector):
    """Reads the DAVIS event frames a bundle would (10 ms) and keeps them; never declares."""

    name = "frames"

    def __init__(self) -> None:
        self.channels = frame_channels(180, 190)
        self.rate_hz = 100.0
        self.seen: list[tuple[float, float, float, float, float]] = []

    def decide(self, state: PlantState, frame: Callable[[], np.ndarray]) -> bool:
        f = frame()
        row = (
            state.t,
            state.onset_s,
            state.drop_mm,
            float(f[0].sum()),
            float(f[1].sum()),
        )
        self.seen.append(row)
        return False


def test_event_frames_show_the_press_then_the_lost_contact() -> None:
    """Without noise effects: the press fires only negative events, the incipient slip only positive ones."""
    scenario, scene, plant = _setup(
        "~scene.effects.vibration_incidents", "~scene.effects.background_events"
    )
    det = _Frames()
    out = scenario.run_trial(
        scene, det, plant, seed=0, condition_index=0, trial=0, condition=SLOW
    )
    seen = pd.DataFrame(det.seen, columns=["t", "onset", "slide", "pos", "neg"])
    before = seen[seen["onset"].isna()]
    # incipient: after the onset, before the object slides (grip constant, only shear)
    lift = seen[seen["onset"].notna() & (seen["slide"] == 0.0)]
    assert (True, 0.0, True, True, 0.0) == (
        bool(out.dropped),
        float(before["pos"].sum()),
        bool(before["neg"].sum() > 0),
        bool(lift["pos"].sum() > 0),
        float(lift["neg"].sum()),
    )


class _WrongFrame(Detector):
    name = "wrong"
    channels = ("pac",)
    rate_hz = 100.0

    def decide(self, state: PlantState, frame: Callable[[], np.ndarray]) -> bool:
        return False


def test_a_detector_reading_another_frame_is_refused() -> None:
    """A bundle whose channels are not the 2 x 180 x 190 event frame is refused by name."""
    with pytest.raises(SlipkitError) as err:
        _trial(_WrongFrame())
    assert str(err.value).startswith(
        "closedloop.detectors.wrong: its bundle reads 1 channels"
    )


def test_an_effect_the_loop_cannot_evaluate_is_refused_by_name() -> None:
    """A scene effect other than the DAVIS event effects is a one-line error naming it."""
    scenario, scene, plant = _setup("+scene.effects.timestamp_jitter={}")
    with pytest.raises(SlipkitError) as err:
        scenario.run_trial(
            scene, _Frames(), plant, seed=0, condition_index=0, trial=0, condition=SLOW
        )
    assert str(err.value).startswith(
        "configs/scene/davis_release.yaml effects ['timestamp_jitter']: the DAVIS "
        "closed loop cannot evaluate them from the plant"
    )


def test_bad_plant_parameter_is_refused_by_name() -> None:
    """area_loss above 1 is a one-line error naming the field."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="closedloop",
            overrides=["closedloop=davis", "closedloop.plant.area_loss=[0.1,1.5]"],
        )
        scen = load_scenario(cfg)
        scene = build_scene(compose("train", [f"scene={scen.scene}"]).scene)
    with pytest.raises(SlipkitError) as err:
        scenario_of(scen).check(scen, scene)
    assert (
        "configs/closedloop/davis.yaml plant.area_loss: must be <= 1; got [0.1, 1.5]"
        == str(err.value)
    )


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """One small DAVIS run: the learned event classifier (8 training trials), 1 seed, 1 trial per lift."""
    out = tmp_path_factory.mktemp("davis") / "cl"
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="closedloop",
            overrides=[
                "closedloop=davis",
                "demo=true",
                "seeds=[0]",
                "trials_per_speed=1",
                "closedloop.demo.detectors=[event_logreg]",
                f"out={out}",
            ],
        )
        closedloop_main(cfg)
    yield pd.read_csv(out / "results.csv"), pd.read_csv(out / "summary.csv")
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()


def test_end_to_end_bounds_and_conditions(small) -> None:  # type: ignore[no-untyped-def]
    """The run covers the three lifts; the oracle keeps every object, no detector none; the bundle decided."""
    results, summary = small
    by = summary.set_index("detector")
    assert (
        [0.03, 0.0949, 0.3],
        ["event_logreg", "oracle", "none", "oracle+20ms"],
        100.0,
        0.0,
        True,
    ) == (
        sorted(results["condition"].unique().tolist()),
        summary["detector"].tolist(),
        by.loc["oracle", "caught_pct"],
        by.loc["none", "caught_pct"],
        bool(
            by.loc["event_logreg", "n_decisions"] > 0
            and math.isfinite(by.loc["event_logreg", "p50_us"])
        ),
    )
