"""BioTac closed loop: grasp, lift and a load change under Su et al.'s grip controller.

Su et al. 2015 (Humanoids, Sec. V-D): the grip force follows the measured tangential
force, ``Fz = Ft / mu + margin`` (margin 10-40 %), and "mu is re-estimated as Ft / Fz
when slip is detected"; slip is detected from the AC pressure (2.2 kHz) or the
tangential-force derivative (300 Hz).

Here each trial: the object (mass, friction, texture) is drawn by the scene model
(:meth:`slipkit.families.biotac.scene.BioTacLiftSlip.sample`: one of the paper's four
objects, contact point, load direction); the hand closes with a light press, lifts the
object (the load rises to ``m g`` over ``lift_s``), holds it, and then the load changes
to ``load_factor m g`` over the condition's time (something is put in the object). The
controller (:class:`FrictionController`, at ``control_hz``) starts from an
overestimate of ``mu`` (``mu_prior`` times the true ``mu_s``), so the lift's first
slip is how it learns ``mu``; a load change faster than the hand's latency and lag
brings a second one. The plant is :class:`~slipkit.closedloop.plant.PinchPlant` with
the scene's ``1 / load_share`` contacts and ``mu_k = mu_kinetic_ratio mu_s``.

Sensor (:class:`BioTacSensor`): the AC pressure is the scene's backbone (baseline plus
``pac_gain dFn/dt`` of the plant's grip) plus the scene's pressure effects evaluated by
their own functions: ``motor_vibration`` and ``white_noise`` on the trial's timeline
(they do not depend on the plant), ``slip_vibration`` drawn on the timeline and gated
per frame by the plant's slides (raised-cosine edges of its ``ramp_s``), and
``quantisation`` on the one-sample frame. The force channels (``fx``, ``fy``, ``fz``,
``ft``, ``fn``) are the contact's: the plant's per-contact tangential force through a
first-order lag of the scene's ``force_drop_tau_s`` (the fall from static to kinetic
friction), along the drawn load direction, plus the grip along the contact normal.
Electrode effects are not evaluated: no closed-loop detector reads the electrodes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from slipkit._options import within
from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.pinch import pinch_trial, run_pinch_trial
from slipkit.closedloop.plant import (
    FORCE_N,
    LAG_S,
    LATENCY_S,
    PHASE_S,
    SUBSTEPS,
    TRAVEL_MM,
    PlantState,
    check_params,
)
from slipkit.closedloop.run import Outcome
from slipkit.closedloop.scenarios import _draw, register_scenario
from slipkit.closedloop.skeleton import GridScenario
from slipkit.errors import SlipkitError
from slipkit.families.biotac.physics import surface_point, tangent_frame
from slipkit.families.biotac.scene import BioTacLiftSlip
from slipkit.sim.core import EFFECTS, Scene, SceneState, draw_effect_params, effect_name

#: Pressure effects of the trial's timeline (no dependence on the plant).
TIMELINE_EFFECTS = frozenset({"motor_vibration", "white_noise"})
#: Pressure effects gated by the plant's slides.
GATED_EFFECTS = frozenset({"slip_vibration"})
#: Pressure effects applied per frame.
FRAME_EFFECTS = frozenset({"quantisation"})
FORCE_CHANNELS = ("fx", "fy", "fz", "ft", "fn")


@dataclass
class FrictionController:
    """Su et al.'s grip law: ``Fz = max(min_N, Ft / mu (1 + margin))``, ``mu = Ft / Fz`` at a declared slip.

    Updates its command at ``control_hz`` from the contact's tangential force ``Ft``
    (N). On a control tick with a declared slip since the last tick it re-estimates
    ``mu = Ft / Fz`` from the measured forces (while the object slides that is the
    kinetic ratio, and the next command is the present grip times ``1 + margin``), when
    ``Ft`` exceeds ``min_ft_N`` (with no load there is nothing to estimate). Closes
    with ``min_N`` at ``close_s``.
    """

    mu: float
    margin: float
    min_N: float
    max_N: float
    close_s: float
    control_hz: float
    min_ft_N: float = 0.05
    _last_tick: int = -1
    _cmd: float = 0.0
    _slip: bool = False

    def command(self, state: PlantState, declared: bool) -> float | None:
        """The new grip command, N (None: unchanged)."""
        if state.t < self.close_s - 1e-12:
            return None
        self._slip = self._slip or declared
        tick = math.floor(state.t * self.control_hz + 1e-6)
        if tick <= self._last_tick:
            return None
        self._last_tick = tick
        ft = float(state.tangential_N)
        if self._slip and ft > self.min_ft_N and state.normal_N > 0:
            self.mu = ft / state.normal_N
        self._slip = False
        self._cmd = min(self.max_N, max(self.min_N, ft / self.mu * (1.0 + self.margin)))
        return self._cmd


class BioTacSensor:
    """AC pressure and contact forces of the plant's state, by the scene's effects (module docstring).

    Parameters
    ----------
    scene : Scene
        A BioTac lift-and-slip scene.
    rng : numpy.random.Generator
        The trial's generator.
    t : numpy.ndarray
        The trial's frame times at the pressure rate, s.
    params : mapping
        The scene model's draw for the trial (object, contact, load direction).
    """

    def __init__(
        self,
        scene: Scene,
        rng: np.random.Generator,
        *,
        t: np.ndarray,
        params: Mapping[str, Any],
    ) -> None:
        model = scene.model
        assert isinstance(model, BioTacLiftSlip)
        self.model = model
        self.rng = rng
        self.t0 = float(t[0])
        self.dt = float(t[1] - t[0])
        texture = float(model.objects[params["object"]].get("texture", 1.0))
        point, normal = surface_point(params["contact_s_mm"], params["contact_phi_rad"])
        del point
        t1, t2 = tangent_frame(normal)
        psi = float(params["load_direction_rad"])
        self.load_dir = np.asarray(-np.cos(psi) * t1 + np.sin(psi) * t2).reshape(3)
        self.normal = np.asarray(normal).reshape(3)
        keys = scene.effect_keys()
        params_by_key = {
            k: draw_effect_params(k, scene.effects[k], rng)[0] for k in keys
        }
        pac_keys = [k for k in keys if params_by_key[k].get("target", "pac") == "pac"]
        known = TIMELINE_EFFECTS | GATED_EFFECTS | FRAME_EFFECTS
        unknown = [k for k in pac_keys if effect_name(k) not in known]
        if unknown:
            raise SlipkitError(
                f"configs/scene/{scene.name}.yaml effects {unknown}: the BioTac closed "
                f"loop cannot evaluate them on the pressure frame by frame; it knows "
                f"{sorted(known)}"
            )
        zero = np.zeros(len(t))
        state = SceneState(time={"pac": t}, signals={"pac": zero}, truth={})
        for key in pac_keys:
            if effect_name(key) in TIMELINE_EFFECTS:
                state = EFFECTS[effect_name(key)](state, rng, **params_by_key[key])
        #: Pressure the plant does not cause (motor hum, noise) at every frame, counts.
        self.timeline = np.asarray(state.signals["pac"], dtype=np.float64)
        self.slip_noise = np.zeros(len(t))
        self.ramp_s = 0.005
        for key in pac_keys:
            if effect_name(key) in GATED_EFFECTS:
                p = params_by_key[key]
                whole = SceneState(
                    time={"pac": t},
                    signals={"pac": zero},
                    truth={
                        "slip_onset_s": float(t[0]) - 1.0,
                        "slip_end_s": float(t[-1]) + 1.0,
                        "texture": texture,
                    },
                )
                out = EFFECTS[effect_name(key)](whole, rng, **p)
                self.slip_noise = self.slip_noise + np.asarray(out.signals["pac"])
                self.ramp_s = max(float(p.get("ramp_s", 0.005)), 1e-9)
        self.frame_keys = [k for k in pac_keys if effect_name(k) in FRAME_EFFECTS]
        self.frame_params = {k: params_by_key[k] for k in self.frame_keys}
        self._ft_stuck = 0.0

    def _gate(self, state: PlantState) -> float:
        """Slip-vibration envelope now: rises from the slide's start, falls after its arrest."""
        if state.sliding:
            u = min(max((state.t - state.slide_start_s) / self.ramp_s, 0.0), 1.0)
            return 0.5 * (1.0 - math.cos(math.pi * u))
        if not math.isnan(state.arrest_s) and state.t - state.arrest_s < self.ramp_s:
            u = (state.t - state.arrest_s) / self.ramp_s
            return 0.5 * (1.0 + math.cos(math.pi * u))
        return 0.0

    def pac(self, state: PlantState) -> float:
        """AC pressure now, counts."""
        i = min(round((state.t - self.t0) / self.dt), len(self.timeline) - 1)
        rate = 0.0 if math.isnan(state.normal_rate_N_s) else state.normal_rate_N_s
        x = (
            self.model.pac_baseline_counts
            + self.model.pac_gain_counts_per_N_s * rate
            + self.timeline[i]
            + self._gate(state) * self.slip_noise[i]
        )
        one = SceneState(
            time={"pac": np.array([state.t])}, signals={"pac": np.array([x])}
        )
        for key in self.frame_keys:
            one = EFFECTS[effect_name(key)](one, self.rng, **self.frame_params[key])
        return float(np.asarray(one.signals["pac"])[0])

    def forces(self, state: PlantState) -> dict[str, float]:
        """The contact's force now, N: ``fx, fy, fz`` (sensor frame), ``ft``, ``fn``.

        While stuck ``Ft`` is the plant's per-contact tangential force; from a slide's
        start it falls from the last stuck reading towards the plant's kinetic value
        with the scene's ``force_drop_tau_s`` (the scene's law, without its incipient
        phase: the plant has none).
        """
        target = 0.0 if math.isnan(state.tangential_N) else state.tangential_N
        tau = self.model.force_drop_tau_s
        if state.sliding and tau > 0:
            age = max(state.t - state.slide_start_s, 0.0)
            ft = target + (self._ft_stuck - target) * math.exp(-age / tau)
        else:
            ft = self._ft_stuck = target
        f = ft * self.load_dir + state.normal_N * self.normal
        return {
            "fx": float(f[0]),
            "fy": float(f[1]),
            "fz": float(f[2]),
            "ft": ft,
            "fn": state.normal_N,
        }

    def frame(
        self, state: PlantState, channels: tuple[str, ...] | None = None
    ) -> np.ndarray:
        """``channels`` of ``state`` in order (``pac`` and/or the force channels); default ``pac``."""
        names = ("pac",) if channels is None else tuple(channels)
        bad = [c for c in names if c != "pac" and c not in FORCE_CHANNELS]
        if bad:
            raise SlipkitError(
                f"closedloop: the BioTac sensor gives {['pac', *FORCE_CHANNELS]}; a "
                f"detector asked for {bad}"
            )
        values: dict[str, float] = {}
        if "pac" in names:
            values["pac"] = self.pac(state)
        if any(c in FORCE_CHANNELS for c in names):
            values.update(self.forces(state))
        return np.array([values[c] for c in names], dtype=np.float64)


#: Declared ranges of the BioTac plant's parameters (configs/closedloop/biotac.yaml says the same).
PLANT_RULES = {
    "mu_prior": within(0.0, 10.0, above=True, span=True),
    "margin": within(0.0, 2.0, span=True),
    "load_factor": within(0.0, 10.0, span=True),
    "min_force_N": within(0.0, 500.0, "N"),
    "max_force_N": FORCE_N,
    "approach_s": PHASE_S,
    "press_s": PHASE_S,
    "lift_s": within(0.0, 10.0, "s", above=True),
    "hold_s": PHASE_S,
    "post_s": PHASE_S,
    "latency_s": LATENCY_S,
    "tau_s": LAG_S,
    "control_hz": within(0.0, 10_000.0, "Hz", above=True),
    "travel_mm": TRAVEL_MM,
    "substeps": SUBSTEPS,
}
#: load change times of the conditions grid, s
CHANGE_S = within(0.0, 10.0, "s", above=True)


def check_plant(plant: Mapping[str, Any]) -> None:
    """Refuse plant parameters outside their declared ranges (names the field)."""
    check_params(plant, PLANT_RULES, optional=("substeps",))


@register_scenario("biotac")
class BioTacScenario(GridScenario):
    """The BioTac lift with a load change (module docstring); conditions: the change's duration, s."""

    condition_label = "load change time (s)"
    family = "BioTac"
    scene_class = BioTacLiftSlip
    scene_title = "a BioTac lift-and-slip scene"
    grid_key = "conditions"
    grid_rule = CHANGE_S

    def check_plant(self, plant: Mapping[str, Any]) -> None:
        """Refuse plant parameters outside their declared ranges (:func:`check_plant`)."""
        check_plant(plant)

    def run_trial(
        self,
        scene: Scene,
        detector: Detector,
        plant: Mapping[str, Any],
        *,
        seed: int,
        condition_index: int,
        trial: int,
        condition: float,
    ) -> Outcome:
        """One lift-and-load-change trial (module docstring)."""
        model = scene.model
        assert isinstance(model, BioTacLiftSlip)
        rng = np.random.default_rng([int(seed), int(condition_index), int(trial)])
        params = model.sample(rng)
        obj = model.objects[params["object"]]
        mass = float(obj["mass_kg"])
        mu_s = float(obj["mu_static"])
        mu_k = model.mu_kinetic_ratio * mu_s
        contacts = max(1, round(1.0 / model.load_share))
        prior = _draw(rng, plant["mu_prior"])
        margin = _draw(rng, plant["margin"])
        factor = _draw(rng, plant["load_factor"])
        close = float(plant["approach_s"])
        lift0 = close + float(plant["press_s"])
        lift1 = lift0 + float(plant["lift_s"])
        change0 = lift1 + float(plant["hold_s"])
        change1 = change0 + float(condition)
        t_end = change1 + float(plant["post_s"])
        rate = model.pac_rate_hz
        times = np.arange(math.ceil(t_end * rate) + 2) / rate
        sensor = BioTacSensor(scene, rng, t=times, params=params)

        def controller() -> FrictionController:
            return FrictionController(
                mu=prior * mu_s,
                margin=margin,
                min_N=float(plant["min_force_N"]),
                max_N=float(plant["max_force_N"]),
                close_s=close,
                control_hz=float(plant["control_hz"]),
            )

        return run_pinch_trial(
            pinch_trial(
                plant,
                mass_kg=mass,
                mu_s=mu_s,
                mu_k=mu_k,
                contacts=contacts,
                lift_s=(lift0, lift1),
                rise_s=(change0, change1),
                load_factor=factor,
                rate_hz=rate,
                sensor=sensor,
                controller=controller,
                t_end=t_end,
            ),
            detector,
            seed=seed,
            condition_index=condition_index,
            trial_index=trial,
            condition=condition,
            object_name=str(params["object"]),
        )
