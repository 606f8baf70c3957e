"""FSR closed loop: a prosthetic pinch holding through knocks, then a load increase that starts a slide.

Gentile et al. 2020 (Mechatronics 70, Sec. 3.3): the IH2 hand grasps an object, a robot
arm applies impulsive disturbances, the touch-and-slip detector runs on the fingertip
FSR at 2 kHz, and "when the object slippage is detected ... the control approach
produces an increment of the grasping force" (the force-and-slippage control of their
ref. [22]); 50 impulsive disturbances gave no false positive.

Here each trial (all times drawn from the trial's generator or set in
``configs/closedloop/fsr.yaml``): the hand is open (no contact: the detector sees the
rest voltage), closes on the object with the holding grip
``F_hold = m g (1 + margin) / (contacts mu_s)`` (through the actuator's latency and
lag), lifts it (the load rises to ``m g``), holds it while the scene's disturbance
effects knock the fingertip, then the load rises linearly to ``load_factor m g`` over
the condition's rise time and starts a slide. The controller
(:class:`StepController`) raises the grip command by ``step_frac`` of the grip on a
declared slip, at most once per ``refractory_s``, up to the hand's ``max_force_N``.

The FSR frame (:class:`FSRSensor`) is made from the plant's state by the scene's own
effects: the normal force is the plant's grip, plus the disturbance effects
(``fsr_disturbance``, ``fsr_impulse_disturbance``) evaluated by their own functions on
the trial's timeline (they do not depend on the plant), plus stick-slip events stepped
frame by frame with ``fsr_slip_events``' law (event rate from Table 3's count law at
the plant's slide speed, each event a ringing force release), through the inverse of
the calibration eq. 6; then the voltage-domain effects (``fsr_polarity``,
``white_noise``, ``quantisation``) by their own functions on the one-sample frame.
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
    G_M_S2,
    LAG_S,
    LATENCY_S,
    MASS_KG,
    MU_K,
    MU_S,
    PHASE_S,
    SUBSTEPS,
    TRAVEL_MM,
    PlantState,
    check_params,
)
from slipkit.closedloop.run import Outcome
from slipkit.closedloop.scenarios import _draw, _span, register_scenario
from slipkit.closedloop.skeleton import GridScenario
from slipkit.errors import SlipkitError
from slipkit.families.fsr.physics import expected_slip_events, voltage_from_force
from slipkit.families.fsr.scene import FSRProbeSlide
from slipkit.sim.core import EFFECTS, Scene, SceneState, draw_effect_params, effect_name

#: Force-domain effects of the plant's trial timeline (no dependence on the plant).
TIMELINE_EFFECTS = frozenset({"fsr_disturbance", "fsr_impulse_disturbance"})
#: Force-domain effects stepped frame by frame from the plant's slide.
RECURSIVE_EFFECTS = frozenset({"fsr_slip_events"})
#: Replaced by the plant: the hand closing through its actuator is the touch.
PLANT_EFFECTS = frozenset({"fsr_touch"})
#: Voltage-domain effects, applied per frame on a one-sample state.
FRAME_EFFECTS = frozenset({"fsr_polarity", "white_noise", "quantisation"})
KNOWN = TIMELINE_EFFECTS | RECURSIVE_EFFECTS | PLANT_EFFECTS | FRAME_EFFECTS


@dataclass
class StepController:
    """Gentile et al.'s grip compensation: on a declared slip, raise the grip by a step.

    Holds ``hold_N`` from ``close_s``; on a declaration (at most once per
    ``refractory_s``) commands ``(1 + step_frac)`` times the larger of the present
    command and the measured grip, up to ``max_N``.
    """

    hold_N: float
    close_s: float
    step_frac: float
    refractory_s: float
    max_N: float
    _cmd: float = 0.0
    _last: float = -math.inf
    _closed: bool = False

    def command(self, state: PlantState, declared: bool) -> float | None:
        """The new grip command, N (None: unchanged)."""
        if not self._closed:
            if state.t < self.close_s - 1e-12:
                return None
            self._closed = True
            self._cmd = self.hold_N
            return self._cmd
        if declared and state.t - self._last >= self.refractory_s - 1e-12:
            self._last = state.t
            self._cmd = min(
                self.max_N, (1.0 + self.step_frac) * max(self._cmd, state.normal_N)
            )
            return self._cmd
        return None


class FSRSensor:
    """The conditioned FSR voltage of the plant's state, made by the scene's effects (module docstring).

    Parameters
    ----------
    scene : Scene
        An FSR probe-slide scene (its calibration, output range and effects).
    rng : numpy.random.Generator
        The trial's generator (effect parameters, disturbance draws, then per-frame noise).
    t : numpy.ndarray
        The trial's frame times, s.
    hold_s : tuple of float
        The hold phase (disturbances land in it, the effects' ``margin_s`` from its ends), s.
    hold_N : float
        The holding grip the disturbance amplitudes scale with, N.
    pass_mm : float
        Length of the sensor the object's slide crosses (the Table 3 count law's pass), mm.
    """

    def __init__(
        self,
        scene: Scene,
        rng: np.random.Generator,
        *,
        t: np.ndarray,
        hold_s: tuple[float, float],
        hold_N: float,
        pass_mm: float,
    ) -> None:
        model = scene.model
        if not isinstance(model, FSRProbeSlide):
            raise SlipkitError(
                f"closedloop.scene: the FSR closed loop needs an FSR probe-slide scene; "
                f"got {type(model).__name__}"
            )
        self.calibration = model.calibration
        self.output_range_V = model.output_range_V
        self.rng = rng
        self.t0 = float(t[0])
        self.dt = float(t[1] - t[0])
        self.pass_mm = float(pass_mm)
        keys = scene.effect_keys()
        unknown = [k for k in keys if effect_name(k) not in KNOWN]
        if unknown:
            raise SlipkitError(
                f"configs/scene/{scene.name}.yaml effects {unknown}: the FSR closed loop "
                f"cannot evaluate them frame by frame; it knows {sorted(KNOWN)}"
            )
        params = {k: draw_effect_params(k, scene.effects[k], rng)[0] for k in keys}
        base = np.full(len(t), float(hold_N))
        volts = voltage_from_force(base, self.calibration, self.output_range_V)
        state = SceneState(
            time={"fsr": t, "truth_contact": t},
            signals={
                "force": base,
                "fsr": volts,
                "disturbance": np.zeros(len(t)),
            },
            truth={
                "phases": {"hold": hold_s},
                "normal_force_N": float(hold_N),
                "calibration": self.calibration,
                "output_range_V": self.output_range_V,
            },
        )
        for key in keys:
            if effect_name(key) in TIMELINE_EFFECTS:
                state = EFFECTS[effect_name(key)](state, rng, **params[key])
        #: Disturbance force on the fingertip at every frame, N.
        self.disturbance_N = np.asarray(state.signals["force"]) - base
        self.disturbed = np.asarray(state.signals["disturbance"]) > 0
        self.frame_keys = [k for k in keys if effect_name(k) in FRAME_EFFECTS]
        self.frame_params = {k: params[k] for k in self.frame_keys}
        slip = [k for k in keys if effect_name(k) in RECURSIVE_EFFECTS]
        self.slip = params[slip[0]] if slip else None
        if self.slip is not None:
            self._check_slip(slip[0], scene.name)
        self._phase = 0.0
        self._next = self._threshold()
        self._events: list[tuple[float, float]] = []  # (time, amplitude N)
        self._was_sliding = False

    def _check_slip(self, key: str, scene_name: str) -> None:
        p = self.slip
        assert p is not None
        decay = float(p.get("decay_s", 0.003))
        jitter = float(p.get("jitter", 0.3))
        if not decay > 0 or not 0 <= jitter < 0.5:
            raise SlipkitError(
                f"configs/scene/{scene_name}.yaml effects.{key}: need decay_s > 0 and "
                f"0 <= jitter < 0.5; got {decay!r}, {jitter!r}"
            )

    def _threshold(self) -> float:
        jitter = float(self.slip.get("jitter", 0.3)) if self.slip else 0.0
        return 1.0 + jitter * float(self.rng.uniform(-1.0, 1.0))

    def _slip_force(self, state: PlantState) -> float:
        """This frame's stick-slip force, N: events at the Table 3 law's rate while sliding."""
        p = self.slip
        if p is None:
            return 0.0
        t = state.t
        amp = _span(p.get("amplitude_frac", (0.08, 0.16)))
        if state.sliding:
            fire = (
                not self._was_sliding
            )  # the break-away is the first event (assumption)
            speed = state.speed_mm_s
            if speed > 0 and state.normal_N > 0:
                pass_s = self.pass_mm / speed
                n = float(
                    expected_slip_events(
                        state.normal_N,
                        pass_s,
                        float(p.get("coeff", 16.81)),
                        float(p.get("force_exponent", 0.3233)),
                        float(p.get("pass_exponent", 0.4486)),
                    )
                )
                self._phase += n / pass_s * self.dt
                if self._phase >= self._next:
                    self._phase -= self._next
                    self._next = self._threshold()
                    fire = True
            if fire:
                a = state.normal_N * float(self.rng.uniform(amp[0], amp[1]))
                self._events.append((t, a))
        self._was_sliding = state.sliding
        decay = float(p.get("decay_s", 0.003))
        ring = float(p.get("ring_hz", 150.0))
        self._events = [(e, a) for e, a in self._events if t - e < 6.0 * decay]
        total = 0.0
        for e, a in self._events:
            tau = t - e
            total -= a * math.exp(-tau / decay) * math.cos(2.0 * math.pi * ring * tau)
        return total

    def force(self, state: PlantState) -> float:
        """Normal force on the FSR now, N (grip + disturbance + stick-slip)."""
        i = min(round((state.t - self.t0) / self.dt), len(self.disturbance_N) - 1)
        return max(
            state.normal_N + self.disturbance_N[i] + self._slip_force(state), 0.0
        )

    def frame(
        self, state: PlantState, channels: tuple[str, ...] | None = None
    ) -> np.ndarray:
        """The conditioned voltage of ``state``, V, shape (1,) (``channels``: ``voltage``)."""
        if channels is not None and tuple(channels) != ("voltage",):
            raise SlipkitError(
                f"closedloop: the FSR sensor gives channel 'voltage'; a detector asked "
                f"for {list(channels)}"
            )
        f = np.array([self.force(state)])
        v = voltage_from_force(f, self.calibration, self.output_range_V)
        one = SceneState(
            time={"fsr": np.array([state.t])},
            signals={"fsr": v},
            truth={"output_range_V": self.output_range_V},
        )
        for key in self.frame_keys:
            one = EFFECTS[effect_name(key)](one, self.rng, **self.frame_params[key])
        return np.asarray(one.signals["fsr"], dtype=np.float64)


#: Declared ranges of the FSR plant's parameters (configs/closedloop/fsr.yaml says the same).
PLANT_RULES = {
    "mass_kg": MASS_KG,
    "mu_s": MU_S,
    "mu_k": MU_K,
    "contacts": within(1, 5, whole_number=True),
    "margin": within(0.0, 2.0, span=True),
    "load_factor": within(1.0, 10.0, span=True),
    "approach_s": PHASE_S,
    "close_s": PHASE_S,
    "lift_s": PHASE_S,
    "hold_s": PHASE_S,
    "post_s": PHASE_S,
    "latency_s": LATENCY_S,
    "tau_s": LAG_S,
    "step_frac": within(0.0, 2.0),
    "refractory_s": within(0.0, 1.0, "s"),
    "max_force_N": FORCE_N,
    "travel_mm": TRAVEL_MM,
    "pass_mm": within(0.0, 100.0, "mm", above=True),
    "substeps": SUBSTEPS,
}
#: load rise times of the conditions grid, s
RISE_S = within(0.0, 10.0, "s", above=True)


def check_plant(plant: Mapping[str, Any]) -> None:
    """Refuse plant parameters outside their declared ranges (names the field)."""
    check_params(plant, PLANT_RULES, optional=("contacts", "substeps"))
    if _span(plant["mu_k"])[1] > _span(plant["mu_s"])[0]:
        raise SlipkitError(
            f"closedloop.plant.mu_k={plant['mu_k']}: must not exceed closedloop.plant.mu_s "
            f"({plant['mu_s']})"
        )
    if _span(plant["load_factor"])[0] <= 1.0 + _span(plant["margin"])[1]:
        raise SlipkitError(
            f"closedloop.plant.load_factor={plant['load_factor']}: must exceed 1 + "
            f"closedloop.plant.margin ({plant['margin']}; else the load increase never "
            "starts a slide)"
        )


@register_scenario("fsr")
class FSRScenario(GridScenario):
    """The FSR prosthetic hold (module docstring); conditions: the load's rise time, s."""

    condition_label = "load rise time (s)"
    family = "FSR"
    scene_class = FSRProbeSlide
    scene_title = "an FSR probe-slide scene"
    grid_key = "conditions"
    grid_rule = RISE_S

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
        """One hold-and-load trial (module docstring)."""
        model = scene.model
        assert isinstance(model, FSRProbeSlide)
        rng = np.random.default_rng([int(seed), int(condition_index), int(trial)])
        mass = _draw(rng, plant["mass_kg"])
        mu_s, mu_k = _draw(rng, plant["mu_s"]), _draw(rng, plant["mu_k"])
        margin = _draw(rng, plant["margin"])
        factor = _draw(rng, plant["load_factor"])
        contacts = int(plant.get("contacts", 2))
        weight = mass * G_M_S2
        hold_N = weight * (1.0 + margin) / (contacts * mu_s)
        close = float(plant["approach_s"])
        lift0 = close + float(plant["close_s"])
        lift1 = lift0 + float(plant["lift_s"])
        rise0 = lift1 + float(plant["hold_s"])
        rise1 = rise0 + float(condition)
        t_end = rise1 + float(plant["post_s"])
        rate = model.rate_hz
        n = math.ceil(t_end * rate) + 2
        times = np.arange(n) / rate
        sensor = FSRSensor(
            scene,
            rng,
            t=times,
            hold_s=(lift1, rise0),
            hold_N=hold_N,
            pass_mm=float(plant["pass_mm"]),
        )

        def controller() -> StepController:
            return StepController(
                hold_N=hold_N,
                close_s=close,
                step_frac=float(plant["step_frac"]),
                refractory_s=float(plant["refractory_s"]),
                max_N=float(plant["max_force_N"]),
            )

        return run_pinch_trial(
            pinch_trial(
                plant,
                mass_kg=mass,
                mu_s=mu_s,
                mu_k=mu_k,
                contacts=contacts,
                lift_s=(lift0, lift1),
                rise_s=(rise0, rise1),
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
            object_name=f"pinch {mass:.3f} kg",
        )
