"""A held object under a rising load with a grip controller that acts on every declared slip.

Shared by the FSR (Gentile et al. 2020) and BioTac (Su et al. 2015) scenarios: the
object is pinched by a force-controlled hand (:class:`~slipkit.closedloop.plant.PinchPlant`),
the hand closes, lifts, holds through disturbances, then the load rises and starts a
slide. Unlike the TacTip catch (one-shot), the detector is consulted on every frame of
the trial and the family's :class:`GripController` may raise the grip on each declared
slip, so a false alarm during the hold raises the grip force, and a late or missed
detection lets the object slide further or out of the grasp.

Outcome columns (:class:`~slipkit.closedloop.run.Outcome`):

* ``onset_s``: the plant's first slip onset; ``declared_s``: the first declaration;
* ``false_alarm``: a declaration while the object is stuck and has not slid for
  ``grace_s`` (before the first onset, or between slides);
* ``delay_ms``: the first other declaration during the first slide (or within
  ``grace_s`` of its arrest), minus the onset (NaN: the first slide was missed);
* ``extra_force_N`` / ``extra_impulse_Ns``: the grip force above a shadow
  controller's, identical but told only the declarations that were not false alarms
  (its own actuator stepped in lock-step), from the first false alarm to the end:
  peak, N, and integral of the positive part, N s;
* ``slip_mm``: the whole slide (all slides), the travel when dropped;
  ``onset_to_arrest_ms``: first onset to the latest re-stick.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any, Protocol

import numpy as np

from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.plant import G_M_S2, Actuator, PinchPlant, PlantState
from slipkit.closedloop.run import Outcome


class GripController(Protocol):
    """The family's grip law: a new grip-force command (N), or None to keep the last one."""

    def command(self, state: PlantState, declared: bool) -> float | None:
        """Called once per frame with the detector's decision on it."""


class FrameSensor(Protocol):
    """Builds the detector's frame of the plant's current state."""

    def frame(self, state: PlantState, channels: tuple[str, ...] | None) -> np.ndarray:
        """The frame: ``channels`` in order (None: the sensor's own), 1-D."""


@dataclass
class PinchTrial:
    """One pinch trial's pieces.

    Attributes
    ----------
    plant : PinchPlant
        The plant (its actuator is the controller's).
    sensor : FrameSensor
        Frames from the plant's state.
    controller, shadow : GripController
        The controller, and an identical one that never sees a declaration (the
        no-detector grip, for the false-alarm cost).
    shadow_actuator : Actuator
        The shadow controller's actuator (same latency and lag).
    t_end : float
        Trial end, s.
    grace_s : float
        A declaration this long after a slide's arrest still counts for that slide, s
        (assumption).
    """

    plant: PinchPlant
    sensor: FrameSensor
    controller: GripController
    shadow: GripController
    shadow_actuator: Actuator
    t_end: float
    grace_s: float = 0.05


def run_pinch_trial(
    trial: PinchTrial,
    detector: Detector,
    *,
    seed: int,
    condition_index: int,
    trial_index: int,
    condition: float,
    object_name: str,
) -> Outcome:
    """Step the plant to ``trial.t_end`` with ``detector`` in the loop; the outcome."""
    plant = trial.plant
    state = plant.state
    dt = 1.0 / plant.rate_hz
    detector.reset()
    declared = math.nan
    first_false = math.nan
    delay = math.nan
    frames = 0
    peak, impulse = 0.0, 0.0
    shadow_force = 0.0
    frame: Callable[[], np.ndarray]
    # A detector at a lower frame rate than the plant (BioTac's 300 Hz force against
    # the 2.2 kHz pressure) sees a frame when its own sample falls due.
    rate = detector.rate_hz or plant.rate_hz
    last_tick = -1
    while state.t < trial.t_end - 1e-12 and not state.dropped:
        tick = math.floor(state.t * rate + 1e-6)
        yes = False
        if tick > last_tick:
            last_tick = tick
            frames += 1
            frame = partial(trial.sensor.frame, state, detector.channels)
            yes = detector.decide(state, frame)
        false = False
        if yes:
            if math.isnan(declared):
                declared = state.t
            recent = not math.isnan(state.arrest_s) and (
                state.t - state.arrest_s <= trial.grace_s
            )
            false = not state.sliding and not recent
            if false and math.isnan(first_false):
                first_false = state.t
            first_slide = state.slide_start_s == state.onset_s
            if not false and first_slide and math.isnan(delay):
                delay = (state.t - state.onset_s) * 1e3
        new = trial.controller.command(state, yes)
        if new is not None:
            plant.actuator.command(state.t, new)
        shadow = trial.shadow.command(state, yes and not false)
        if shadow is not None:
            trial.shadow_actuator.command(state.t, shadow)
        if not math.isnan(first_false):
            extra = state.normal_N - shadow_force
            peak = max(peak, extra)
            impulse += max(extra, 0.0) * dt
        t0 = state.t
        state = plant.step()
        h = dt / plant.substeps
        for i in range(plant.substeps):
            shadow_force = trial.shadow_actuator.advance(t0 + i * h, h)
        shadow_force = min(max(shadow_force, 0.0), plant.max_force_N)
    onset = state.onset_s
    false_alarm = not math.isnan(first_false)
    dropped = bool(state.dropped or state.sliding)
    return Outcome(
        detector=detector.name,
        seed=int(seed),
        condition_index=int(condition_index),
        trial=int(trial_index),
        condition=float(condition),
        mass_kg=float(plant.mass_kg),
        object=object_name,
        onset_s=onset,
        declared_s=declared,
        false_alarm=false_alarm,
        delay_ms=delay,
        arrest_s=state.arrest_s,
        slip_mm=plant.travel_mm if dropped else float(state.drop_mm),
        dropped=dropped,
        onset_to_arrest_ms=(
            (state.arrest_s - onset) * 1e3
            if not (dropped or math.isnan(state.arrest_s) or math.isnan(onset))
            else math.nan
        ),
        extra_force_N=float(peak) if false_alarm else 0.0,
        extra_impulse_Ns=float(impulse) if false_alarm else 0.0,
        frames=frames,
    )


def pinch_trial(
    plant: Mapping[str, Any],
    *,
    mass_kg: float,
    mu_s: float,
    mu_k: float,
    contacts: int,
    lift_s: tuple[float, float],
    rise_s: tuple[float, float],
    load_factor: float,
    rate_hz: float,
    sensor: FrameSensor,
    controller: Callable[[], GripController],
    t_end: float,
) -> PinchTrial:
    """The pinch trial of a scenario's plant parameters (``latency_s``, ``tau_s``,
    ``max_force_N``, ``travel_mm``, ``substeps``): an object of ``mass_kg`` between
    ``contacts`` pads, lifted over ``lift_s`` (its weight taken up), then loaded to
    ``load_factor`` x its weight over ``rise_s`` (:func:`load_profile`); the controller
    and its shadow are two calls of ``controller``, each with its own actuator of the
    plant's latency and lag."""
    weight = mass_kg * G_M_S2
    latency, tau = float(plant["latency_s"]), float(plant["tau_s"])
    pinch = PinchPlant(
        mass_kg=mass_kg,
        mu_s=mu_s,
        mu_k=mu_k,
        contacts=contacts,
        load=load_profile(
            weight_N=weight,
            lift_s=lift_s,
            rise_s=rise_s,
            final_N=load_factor * weight,
        ),
        actuator=Actuator(latency, tau),
        max_force_N=float(plant["max_force_N"]),
        travel_mm=float(plant["travel_mm"]),
        rate_hz=rate_hz,
        substeps=int(plant.get("substeps", 1)),
    )
    return PinchTrial(
        plant=pinch,
        sensor=sensor,
        controller=controller(),
        shadow=controller(),
        shadow_actuator=Actuator(latency, tau),
        t_end=t_end,
    )


def load_profile(
    *,
    weight_N: float,
    lift_s: tuple[float, float],
    rise_s: tuple[float, float],
    final_N: float,
) -> Callable[[float], float]:
    """``Q(t)``: 0, the weight over ``lift_s`` (raised cosine), then a linear rise to ``final_N`` over ``rise_s``, N."""
    l0, l1 = lift_s
    r0, r1 = rise_s

    def q(t: float) -> float:
        if t <= l0:
            return 0.0
        if t < l1:
            return weight_N * 0.5 * (1.0 - math.cos(math.pi * (t - l0) / (l1 - l0)))
        if t <= r0:
            return weight_N
        if t < r1:
            return weight_N + (final_N - weight_N) * (t - r0) / (r1 - r0)
        return final_N

    return q
