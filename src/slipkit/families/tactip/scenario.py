"""TacTip closed loop: the paper's gravity drop with the arm retracting at 0.1-20 mm/s.

James, Pestell, Lepora 2018 (RA-L 3(4), Sec. IV-C, Table II): an object on a vertical
rail is held against the TacTip by friction; the arm retracts at a constant speed, the
grip falls until the object slips, and "when slip is detected, the arm moves
immediately back to prevent the object from falling" (two consecutive slip frames
trigger the response). Success = the object caught (two plateaus in its height).

Here the plant is :class:`~slipkit.closedloop.plant.GraspPlant` (Hertz contact, the
scene's mass, friction and stiffness), stepped at the camera rate; the trial's
parameters are drawn by the scene model itself
(:meth:`slipkit.families.tactip.scene.TacTipGravityDrop.sample` and ``trial``), with the
retraction speed set from the scenario's grid. Every frame's pins come from the
plant's *current* state through the scene's listed effects (:class:`TacTipSensor`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from functools import cached_property, partial
from typing import Any

import numpy as np

from slipkit._options import within
from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.plant import (
    LAG_S,
    LATENCY_S,
    SUBSTEPS,
    TRAVEL_MM,
    Actuator,
    GraspPlant,
    PlantState,
    check_params,
    span,
)
from slipkit.closedloop.run import Outcome
from slipkit.closedloop.scenarios import register_scenario
from slipkit.closedloop.skeleton import GridScenario
from slipkit.errors import SlipkitError
from slipkit.families.tactip.physics import normal_force_N
from slipkit.families.tactip.scene import TacTipGravityDrop, TacTipTrial
from slipkit.sim.core import (
    EFFECTS,
    Scene,
    SceneState,
    draw_effect_params,
    effect_name,
)

#: Effects that move the skin as a function of the contact state (grip, load ratio,
#: time since onset): evaluated per frame on a one-frame state, held at the arrest.
SKIN_EFFECTS = frozenset({"skin_stretch", "snap_back", "mindlin_creep"})
#: Effects independent from frame to frame (detection noise, lost pins).
FRAME_EFFECTS = frozenset({"pin_jitter", "missing_pins", "missing_pin_frames"})
#: Effects with memory across frames, stepped recursively here.
RECURSIVE_EFFECTS = frozenset({"slip_sliding"})


@dataclass(frozen=True)
class _TrialAt(TacTipTrial):
    """The scene's trial seen at one plant state: indentation fixed, onset from the plant.

    The TacTip effects read the contact only through ``indentation(t)`` (and what
    derives from it: normal force, load ratio, contact weights) and ``onset_s``;
    with these two replaced, the scene's own effect functions map the closed-loop
    state to pins.
    """

    depth_mm: float = 0.0

    def indentation(self, t: np.ndarray) -> np.ndarray:
        """The plant's indentation at every ``t`` (mm)."""
        return np.full(np.shape(t), self.depth_mm, dtype=np.float64)

    @cached_property
    def _weights(self) -> np.ndarray:
        # The indentation is fixed, so the contact weights are the same at every t:
        # computed once per state instead of once per effect (the loop's hot spot).
        return TacTipTrial.weights(self, np.zeros(1))[0]

    def weights(self, t: np.ndarray) -> np.ndarray:
        """Contact weight of every pin at every ``t``, shape (T, N) (the scene's, cached)."""
        return np.broadcast_to(self._weights, (np.size(t), len(self._weights)))


def _trial_at(trial: TacTipTrial, depth_mm: float, onset_s: float) -> _TrialAt:
    values = {f.name: getattr(trial, f.name) for f in fields(TacTipTrial)}
    values["onset_s"] = onset_s
    return _TrialAt(**values, depth_mm=float(depth_mm))


class TacTipSensor:
    """Pins of one frame from the plant's state, by the effects the scene lists.

    Reused from the simulator: the scene model's rest layout and radial spreading
    (the first lines of :meth:`TacTipGravityDrop.base`, repeated in :meth:`base`
    because ``base`` builds a whole trial), and every listed effect function itself
    (``slipkit.families.tactip.effects``), called on a one-frame :class:`SceneState`
    whose trial is the plant's state (:class:`_TrialAt`). Per-trial draws of effect
    parameters use :func:`slipkit.sim.core.draw_effect_params`, as ``Scene.run_trial``
    does. One effect has memory across frames, ``slip_sliding`` (an AR(1) process);
    it is stepped here with the same law (``x_k = phi x_(k-1) + e_k``,
    ``phi = exp(-dt / corr_s)``, stationary s.d. ``sigma_mm``, envelope
    ``1 - exp(-tau / ramp_s)`` times the contact weight) one frame at a time.

    After the arrest the skin re-sticks: the skin effects are held at the arrest's
    state (assumption: the stuck skin keeps its stretch) and the sliding disorder
    decays with ``exp(-(t - t_arrest) / ramp_s)`` (assumption).

    Parameters
    ----------
    scene : Scene
        The TacTip scene (model + effects), ``slipkit.sim.commands.build_scene``.
    trial : TacTipTrial
        The trial's physical parameters (from the scene model).
    rng : numpy.random.Generator
        The trial's generator (effect-parameter draws, then per-frame noise).
    """

    def __init__(
        self, scene: Scene, trial: TacTipTrial, rng: np.random.Generator
    ) -> None:
        model = scene.model
        if not isinstance(model, TacTipGravityDrop):
            raise SlipkitError(
                f"closedloop.scene: the TacTip closed loop needs a TacTip gravity-drop "
                f"scene; got {type(model).__name__}"
            )
        self.model = model
        self.scene_name = scene.name
        self.trial = trial
        self.rng = rng
        self.keys = scene.effect_keys()
        unknown = [
            k
            for k in self.keys
            if effect_name(k) not in SKIN_EFFECTS | FRAME_EFFECTS | RECURSIVE_EFFECTS
        ]
        if unknown:
            raise SlipkitError(
                f"configs/scene/{scene.name}.yaml effects {unknown}: cannot be evaluated one frame at a "
                f"time by the closed loop; it knows {sorted(SKIN_EFFECTS | FRAME_EFFECTS | RECURSIVE_EFFECTS)}"
            )
        self.params: dict[str, dict[str, Any]] = {}
        for key in self.keys:
            kwargs, _ = draw_effect_params(key, scene.effects[key], rng)
            self.params[key] = kwargs
        self.dt = 1.0 / model.rate_hz
        self._ar: np.ndarray | None = None

    def base(self, depth_mm: float) -> np.ndarray:
        """Rest pins spread radially by the indentation, shape (N, 2), mm."""
        tr = _trial_at(self.trial, depth_mm, math.inf)
        w = tr.weights(np.zeros(1))[0]
        spread = tr.radial_gain * depth_mm / tr.tip_radius_mm * w
        return self.trial.rest_xy * (1.0 + spread[:, None])

    def _sliding(self, key: str, state: PlantState, weights: np.ndarray) -> np.ndarray:
        """This frame's ``slip_sliding`` displacement, shape (N, 2), mm."""
        onset = state.onset_s
        if math.isnan(onset) or state.t < onset:
            return np.zeros_like(self.trial.rest_xy)
        p = self.params[key]
        sigma, corr, ramp = (
            float(p.get("sigma_mm", 0.03)),
            float(p.get("corr_s", 0.02)),
            float(p.get("ramp_s", 0.03)),
        )
        if sigma < 0 or not corr > 0 or not ramp > 0:
            raise SlipkitError(
                f"configs/scene/{self.scene_name}.yaml effects.{key}: need sigma_mm >= 0, corr_s > 0, "
                f"ramp_s > 0; got {sigma!r}, {corr!r}, {ramp!r}"
            )
        phi = math.exp(-self.dt / corr)
        drive = self.rng.normal(0.0, sigma, size=self.trial.rest_xy.shape)
        if self._ar is None:
            self._ar = drive  # stationary from the first frame
        else:
            self._ar = phi * self._ar + math.sqrt(1.0 - phi**2) * drive
        envelope = -math.expm1(-(state.t - onset) / ramp)
        if not math.isnan(state.arrest_s):
            envelope *= math.exp(-(state.t - state.arrest_s) / ramp)
        return self._ar * (envelope * weights)[:, None]

    def frame(self, state: PlantState) -> np.ndarray:
        """Pins for ``state``: ``x0..x{N-1}, y0..y{N-1}`` (mm, NaN: not detected), shape (2N,)."""
        arrested = not math.isnan(state.arrest_s)
        skin_t = state.arrest_s if arrested else state.t
        skin_depth = self._arrest_depth if arrested else state.indentation_mm
        if not arrested:
            self._arrest_depth = state.indentation_mm
        onset = math.inf if math.isnan(state.onset_s) else state.onset_s
        now = _trial_at(self.trial, state.indentation_mm, onset)
        skin = now if not arrested else _trial_at(self.trial, skin_depth, onset)
        weights = now.weights(np.zeros(1))[0]
        spread = now.radial_gain * state.indentation_mm / now.tip_radius_mm * weights
        pins = (self.trial.rest_xy * (1.0 + spread[:, None]))[None]
        for key in self.keys:
            name = effect_name(key)
            if name in RECURSIVE_EFFECTS:
                pins = pins + self._sliding(key, state, weights)[None]
                continue
            at_skin = name in SKIN_EFFECTS
            one = SceneState(
                time={"pins": np.array([skin_t if at_skin else state.t])},
                signals={"pins": pins},
                truth={"tactip": skin if at_skin else now},
            )
            pins = np.asarray(
                EFFECTS[name](one, self.rng, **self.params[key]).signals["pins"]
            )
        return np.concatenate([pins[0, :, 0], pins[0, :, 1]])

    _arrest_depth: float = 0.0


def pin_channels(n_pins: int) -> tuple[str, ...]:
    """The raw ``pins`` stream's channels in order: ``x0..x{N-1}, y0..y{N-1}``."""
    n = int(n_pins)
    return tuple(f"x{i}" for i in range(n)) + tuple(f"y{i}" for i in range(n))


def check_frame(detector: Detector, sensor: TacTipSensor, scene_name: str) -> None:
    """Refuse a detector whose frame is not the sensor's (channels in order, frame rate).

    :meth:`TacTipSensor.frame` makes the raw ``pins`` stream (:func:`pin_channels` of
    the scene's pin count) at the camera rate; a bundle exported from a run on another
    pin count or rate reads something else.
    """
    if detector.channels is None:
        return
    want = pin_channels(len(sensor.trial.rest_xy))
    got = tuple(detector.channels)
    if got != want:
        first = next(
            (i for i, (a, b) in enumerate(zip(got, want, strict=False)) if a != b),
            min(len(got), len(want)),
        )
        raise SlipkitError(
            f"closedloop.detectors.{detector.name}: its bundle reads {len(got)} channels, "
            f"the closed loop's configs/scene/{scene_name}.yaml makes {len(want)} pin "
            f"channels ({want[0]}..{want[-1]}); they first differ at position {first}"
        )
    rate = sensor.model.rate_hz
    if detector.rate_hz is not None and not math.isclose(
        float(detector.rate_hz), float(rate), rel_tol=1e-6
    ):
        raise SlipkitError(
            f"closedloop.detectors.{detector.name}: its bundle reads frames at "
            f"{detector.rate_hz:g} Hz, the closed loop's configs/scene/{scene_name}.yaml "
            f"camera runs at {rate:g} Hz"
        )


def open_loop_force(trial: TacTipTrial, t: float) -> float:
    """Grip force the retraction alone would give at ``t`` (no response), N."""
    depth = float(trial.indentation(np.array([t]))[0])
    return float(normal_force_N(np.asarray(depth), trial.stiffness))


def draw_trial(
    model: TacTipGravityDrop,
    rng: np.random.Generator,
    *,
    speed_mm_s: float,
    onset_s: tuple[float, float],
) -> tuple[dict[str, Any], TacTipTrial]:
    """One trial's parameters (the scene model's draw, speed from the grid) and physics."""
    params = model.sample(rng)
    params["speed_mm_s"] = float(speed_mm_s)
    params["onset_s"] = float(rng.uniform(*onset_s))
    return params, model.trial(params)


#: Declared ranges of the TacTip plant's parameters (configs/closedloop/tactip.yaml says the same).
PLANT_RULES = {
    "onset_s": within(0.0, 10.0, "s", span=True),
    "post_s": within(0.0, 10.0, "s", above=True),
    "latency_s": LATENCY_S,
    "tau_s": LAG_S,
    "catch_mm_s": within(0.0, 1000.0, "mm/s", above=True),
    "catch_indentation_mm": within(0.0, 20.0, "mm", above=True),
    "travel_mm": TRAVEL_MM,
    "substeps": SUBSTEPS,
}
#: retraction speeds of the conditions grid, mm/s
SPEED_MM_S = within(0.0, 1000.0, "mm/s", above=True)


def check_scenario(plant: Mapping[str, Any]) -> None:
    """Refuse plant parameters outside their declared ranges (names the field)."""
    check_params(plant, PLANT_RULES, optional=("substeps",))


def run_tactip_trial(
    scene: Scene,
    detector: Detector,
    plant_cfg: Mapping[str, Any],
    *,
    seed: int,
    condition_index: int,
    trial: int,
    condition: float,
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
    seed, condition_index, trial : int
        The draw (``default_rng([seed, condition_index, trial])``).
    condition : float
        Retraction speed, mm/s.
    """
    speed_mm_s = float(condition)
    model = scene.model
    if not isinstance(model, TacTipGravityDrop):
        raise SlipkitError(
            f"closedloop.scene: the TacTip closed loop needs a TacTip gravity-drop "
            f"scene; got {type(model).__name__}"
        )
    rng = np.random.default_rng([int(seed), int(condition_index), int(trial)])
    lo, hi = span(plant_cfg["onset_s"])
    params, tr = draw_trial(model, rng, speed_mm_s=speed_mm_s, onset_s=(lo, hi))
    sensor = TacTipSensor(scene, tr, rng)
    check_frame(detector, sensor, scene.name)
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
        condition_index=int(condition_index),
        trial=int(trial),
        condition=float(speed_mm_s),
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


@register_scenario("tactip")
class TacTipScenario(GridScenario):
    """The TacTip gravity drop (module docstring): retraction speeds, one-shot catch."""

    condition_label = "speed (mm/s)"
    family = "TacTip"
    scene_class = TacTipGravityDrop
    scene_title = "a TacTip gravity-drop scene"
    grid_key = "speeds"
    grid_rule = SPEED_MM_S

    def check_plant(self, plant: Mapping[str, Any]) -> None:
        """Refuse plant parameters that cannot run (:func:`check_scenario`)."""
        check_scenario(plant)

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
        """One gravity-drop trial (:func:`run_tactip_trial`)."""
        return run_tactip_trial(
            scene,
            detector,
            plant,
            seed=seed,
            condition_index=condition_index,
            trial=trial,
            condition=condition,
        )
