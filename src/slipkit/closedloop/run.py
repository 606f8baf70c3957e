"""Run closed-loop trials: plant, sensor, detector and the paper's controller in one loop.

Per frame (``1 / rate_hz``): the sensor frame is built from the plant's current state,
the detector decides, on a declared slip the controller issues its response (the
actuator delivers it after its latency and lag), then the plant advances one frame.
The controller is the paper's one-shot response, so once slip is declared the
detector is no longer consulted and the plant runs on until the object is arrested,
dropped, or (a false alarm) the time the open-loop retraction would have let it slip.

Every trial of one seed uses the same draws for every detector (trial ``i`` at speed
``j`` of seed ``s`` draws from ``default_rng([s, j, i])``), so detectors are compared
on identical objects and noise up to their first declaration.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from functools import partial
from typing import Any

import numpy as np

from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.plant import Actuator, GraspPlant
from slipkit.closedloop.tactip import TacTipSensor, draw_trial, open_loop_force
from slipkit.errors import SlipkitError
from slipkit.sim.core import Scene
from slipkit.sim.scenes.tactip import TacTipGravityDrop


@dataclass(frozen=True)
class Outcome:
    """One closed-loop trial.

    Attributes
    ----------
    detector : str
        Detector name.
    seed, speed_index, trial : int
        Which draw.
    speed_mm_s : float
        Arm retraction speed, mm/s.
    mass_kg : float
        Object mass, kg.
    object : str
        Stimulus.
    onset_s : float
        Plant slip onset, s (NaN: never slipped).
    declared_s : float
        First declared slip, s (NaN: never).
    false_alarm : bool
        Declared before the plant slipped.
    delay_ms : float
        Declared minus onset, ms (NaN unless declared at or after the onset).
    arrest_s : float
        When the slip stopped, s (NaN: not arrested).
    slip_mm : float
        Distance slid by the end (the plant's travel when dropped), mm.
    dropped : bool
        The object was lost (slid past the travel or still sliding at the end).
    onset_to_arrest_ms : float
        Arrest minus onset, ms (NaN unless arrested).
    extra_force_N, extra_impulse_Ns : float
        Grip force above the open-loop retraction's between a false alarm and the
        time the retraction would have let the object slip: peak (N) and integral
        (N s); 0 without a false alarm.
    frames : int
        Frames the detector saw.
    """

    detector: str
    seed: int
    speed_index: int
    trial: int
    speed_mm_s: float
    mass_kg: float
    object: str
    onset_s: float
    declared_s: float
    false_alarm: bool
    delay_ms: float
    arrest_s: float
    slip_mm: float
    dropped: bool
    onset_to_arrest_ms: float
    extra_force_N: float
    extra_impulse_Ns: float
    frames: int

    def row(self) -> dict[str, Any]:
        """The outcome as a flat dict (one CSV row)."""
        return asdict(self)


def run_tactip_trial(
    scene: Scene,
    detector: Detector,
    plant_cfg: Mapping[str, Any],
    *,
    seed: int,
    speed_index: int,
    trial: int,
    speed_mm_s: float,
) -> Outcome:
    """One TacTip gravity-drop trial with ``detector`` in the loop.

    Parameters
    ----------
    scene : Scene
        The TacTip scene (model draws the object; effects make the pins).
    detector : Detector
        Decides per frame.
    plant_cfg : mapping
        ``latency_s``, ``tau_s`` (actuator, s), ``catch_mm_s`` (arm speed back in,
        mm/s), ``catch_indentation_mm`` (where the arm stops pressing, mm),
        ``travel_mm`` (slide that loses the object, mm), ``onset_s``
        (``[lo, hi]``, s: when the open-loop retraction would start the slip),
        ``post_s`` (s simulated after that onset at most), ``substeps``.
    seed, speed_index, trial : int
        The draw (``default_rng([seed, speed_index, trial])``).
    speed_mm_s : float
        Retraction speed, mm/s.
    """
    model = scene.model
    if not isinstance(model, TacTipGravityDrop):
        raise SlipkitError(
            f"closedloop.scene: the TacTip closed loop needs a TacTip gravity-drop "
            f"scene; got {type(model).__name__}"
        )
    rng = np.random.default_rng([int(seed), int(speed_index), int(trial)])
    lo, hi = (float(v) for v in plant_cfg["onset_s"])
    params, tr = draw_trial(model, rng, speed_mm_s=speed_mm_s, onset_s=(lo, hi))
    sensor = TacTipSensor(scene, tr, rng)
    actuator = Actuator(
        float(plant_cfg["latency_s"]), float(plant_cfg["tau_s"]), initial=-speed_mm_s
    )
    plant = GraspPlant(
        mass_kg=float(params["mass_kg"]),
        mu_s=tr.mu_s,
        mu_k=tr.mu_k,
        stiffness=tr.stiffness,
        indentation_mm=float(tr.indentation(np.zeros(1))[0]),
        arm_mm_s=-speed_mm_s,
        actuator=actuator,
        travel_mm=float(plant_cfg["travel_mm"]),
        max_indentation_mm=float(plant_cfg["catch_indentation_mm"]),
        rate_hz=model.rate_hz,
        substeps=int(plant_cfg.get("substeps", 8)),
    )
    detector.reset()
    dt = 1.0 / model.rate_hz
    t_end = tr.onset_s + float(plant_cfg["post_s"])
    declared = math.nan
    frames = 0
    peak, impulse = 0.0, 0.0
    state = plant.state
    while state.t < t_end and not state.dropped:
        if math.isnan(declared):
            frames += 1
            if detector.decide(state, partial(sensor.frame, state)):
                declared = state.t
                actuator.command(state.t, float(plant_cfg["catch_mm_s"]))
        else:
            slipped = not math.isnan(state.onset_s)
            if slipped and not state.sliding:
                break  # arrested
            if not slipped and state.t >= tr.onset_s:
                break  # a false alarm held the object past its open-loop onset
            if not slipped:
                extra = state.normal_N - open_loop_force(tr, state.t)
                peak = max(peak, extra)
                impulse += max(extra, 0.0) * dt
        state = plant.step()
    onset = state.onset_s
    false_alarm = not math.isnan(declared) and (math.isnan(onset) or declared < onset)
    delay = (
        (declared - onset) * 1e3
        if not (math.isnan(declared) or math.isnan(onset) or false_alarm)
        else math.nan
    )
    dropped = state.dropped or state.sliding
    travel = float(plant_cfg["travel_mm"])
    return Outcome(
        detector=detector.name,
        seed=int(seed),
        speed_index=int(speed_index),
        trial=int(trial),
        speed_mm_s=float(speed_mm_s),
        mass_kg=float(params["mass_kg"]),
        object=str(params["object"]),
        onset_s=onset,
        declared_s=declared,
        false_alarm=bool(false_alarm),
        delay_ms=delay,
        arrest_s=state.arrest_s,
        slip_mm=travel if dropped else float(state.drop_mm),
        dropped=bool(dropped),
        onset_to_arrest_ms=(
            (state.arrest_s - onset) * 1e3
            if not (dropped or math.isnan(state.arrest_s))
            else math.nan
        ),
        extra_force_N=float(peak) if false_alarm else 0.0,
        extra_impulse_Ns=float(impulse) if false_alarm else 0.0,
        frames=frames,
    )


def speed_grid(lo: float, hi: float, n: int) -> list[float]:
    """``n`` log-spaced speeds from ``lo`` to ``hi`` (mm/s), rounded to 3 significant digits."""
    return [float(f"{v:.3g}") for v in np.geomspace(lo, hi, int(n))]


def run_detector(
    scene: Scene,
    detector: Detector,
    plant_cfg: Mapping[str, Any],
    *,
    seeds: Sequence[int],
    speeds: Sequence[float],
    trials_per_speed: int,
) -> list[Outcome]:
    """Every (seed, speed, trial) with ``detector`` in the loop."""
    out: list[Outcome] = []
    for seed in seeds:
        for j, speed in enumerate(speeds):
            for i in range(int(trials_per_speed)):
                out.append(
                    run_tactip_trial(
                        scene,
                        detector,
                        plant_cfg,
                        seed=seed,
                        speed_index=j,
                        trial=i,
                        speed_mm_s=speed,
                    )
                )
    return out
