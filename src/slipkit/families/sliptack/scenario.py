"""SlipTack closed loop: an object pulled out of, or dropping through, a loosened grip; regrasp.

SlipTack paper (seed 000; ``../shared/PAPERS.md``): Sec. IV-C's speed trials (an object
pulled across the nibs at 10-100 mm/s) and Sec. IV-E's regrasp demonstration (a 283 g
basswood object released from a parallel-jaw gripper slides down; the controller
"interpreted the sensor signals over a 0.03 s period", then the gripper closed after
"the 0.12 s nominal motor response time").

The plant (:class:`SlipTackPlant`) is a parallel-jaw grip of axial stiffness ``k_a``:
the fingers set the axial nib deflection ``x`` (mm), the grip force is ``N = k_a x``
and Coulomb friction decides (Johnson, *Contact Mechanics*, 1985, Sec. 7.1):

* **drop** (condition 0): the load is the weight ``m g``; at the release the fingers
  open (``x`` relaxes to the trial's opened deflection with the scene's
  ``opening_time_s``); the object breaks away when ``m g > mu_s N`` and slides with
  ``m a = m g - mu_k N`` (eq. 4); it re-sticks when its speed is back at zero with
  ``m g <= mu_s N``;
* **pull** (condition = pull speed, mm/s): at the pull start a string pulls the object
  with tension ``Q`` (a force-limited pull, drawn per trial above the grip's static
  friction); the object slides at the pull speed while ``Q > mu_k N`` and stops when
  kinetic friction reaches the tension (the pull can no longer move it).

Controller (the paper's regrasp): on a declared slip it reads ``read_s`` more of the
signal, the motor responds ``motor_s`` later, then the fingers close towards
``regrasp_mm`` with a first-order lag ``close_tau_s``. One-shot, as TacTip's. The object
is lost when its slide exceeds ``travel_mm`` or it is still sliding at the end.

The sensor frame (:class:`SlipTackSensor`): the 1 kHz coupled-mode nib signal the
``sliptack_pull`` / ``sliptack_drop`` scenes make, built at every frame from the plant's
current slip speed and grip by the scenes' own effect list: ``stick_slip``'s nib
oscillator (eqs. 1-2) stepped exactly through time (:class:`NibOscillator`: the law of
:func:`slipkit.families.sliptack.physics.cycles_quasi_static`, one frame at a time, with the
adhesion term of :func:`slipkit.families.sliptack.effects.stick_slip`), and the memoryless
effects (``gross_deflection``, ``white_noise``) called as functions on a one-frame
:class:`~slipkit.sim.core.SceneState`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from omegaconf import DictConfig

from slipkit._options import within
from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.plant import (
    LAG_S,
    SUBSTEPS,
    TRAVEL_MM,
    PlantState,
    SteppedPlant,
    check_grid,
    check_params,
    span,
)
from slipkit.closedloop.run import Outcome, speed_grid
from slipkit.closedloop.scenarios import register_scenario
from slipkit.closedloop.skeleton import GridScenario
from slipkit.errors import SlipkitError
from slipkit.families.sliptack.physics import G_M_S2, natural_frequency
from slipkit.families.sliptack.scene import SlipTackDrop, SlipTackPull
from slipkit.sim.core import EFFECTS, Scene, SceneState, draw_effect_params, effect_name

#: Effects called per frame as functions of the plant's state (no memory across frames).
FRAME_EFFECTS = frozenset({"gross_deflection", "white_noise"})
#: Effects with memory across frames, stepped here.
RECURSIVE_EFFECTS = frozenset({"stick_slip"})

_TWO_PI = 2.0 * math.pi


class NibOscillator:
    """One nib's stick-slip (SlipTack eqs. 1-2), advanced exactly over any interval.

    Stick: the nib moves with the object (``u' = v``) until ``k_l u`` reaches the
    breakaway force ``mu_s F_n + A_n``. Slip: ``M u'' = mu_k F_n - k_l u`` (eq. 1),
    solved in closed form from the current ``(u, u')``; it re-sticks when the relative
    velocity returns to zero, ``u' = v`` crossed upwards. Within one call the object
    speed ``v`` and the per-nib load ``F_n`` are held (a zero-order hold of the plant's
    state over a frame); events inside the interval are found exactly, so a 1 kHz frame
    does not quantise the 130.8 Hz nib's cycles. With constant ``v`` and ``F_n`` this is
    :func:`slipkit.families.sliptack.physics.cycles_constant_speed` (a test checks the period).

    Written by hand: the scene's effect integrates a whole trial's cycles from a known
    motion, and the closed loop only knows the motion up to the current frame.

    Parameters
    ----------
    M_kg, k_l_N_m : float
        Nib mass (kg) and lateral stiffness (N/m).
    adhesion : mapping, optional
        ``adhesion_N``, ``adhesion_cv``, ``adhesion_exponent``,
        ``adhesion_ref_speed_mm_s`` (the material row): cycle ``n``'s extra breakaway
        force ``A_n = 2 adhesion_N r / (1 + r) G_n``, ``r = (v / ref)^exponent``,
        ``G_n`` gamma with mean 1 and coefficient of variation ``adhesion_cv`` (the
        ``stick_slip`` effect's law), drawn at each re-stick.
    rng : numpy.random.Generator, optional
        Draws ``G_n`` (needed when ``adhesion_N > 0``).

    Attributes
    ----------
    u_m, w_m_s : float
        Nib deflection (m) and velocity (m/s).
    stuck : bool
        Whether the nib sticks to the object now.
    """

    def __init__(
        self,
        *,
        M_kg: float,
        k_l_N_m: float,
        adhesion: Mapping[str, float] | None = None,
        rng: np.random.Generator | None = None,
    ) -> None:
        self.k_l = float(k_l_N_m)
        self.w0 = float(natural_frequency(M_kg, k_l_N_m))
        ad = dict(adhesion or {})
        self.adhesion_N = float(ad.get("adhesion_N", 0.0))
        self.adhesion_cv = float(ad.get("adhesion_cv", 0.0))
        self.adhesion_exp = float(ad.get("adhesion_exponent", 0.0))
        self.adhesion_ref = float(ad.get("adhesion_ref_speed_mm_s", 50.0)) * 1e-3
        self.rng = rng
        self.u_m = 0.0
        self.w_m_s = 0.0
        self.stuck = True
        self.excess_N = 0.0
        self._draw_excess(0.0)

    def _draw_excess(self, v: float) -> None:
        if self.adhesion_N <= 0.0:
            self.excess_N = 0.0
            return
        r = (max(v, 0.0) / self.adhesion_ref) ** self.adhesion_exp
        cv = self.adhesion_cv
        if cv > 0:
            if self.rng is None:
                raise ValueError("NibOscillator: adhesion_cv > 0 needs an rng")
            gain = float(self.rng.gamma(1.0 / cv**2, cv**2))
        else:
            gain = 1.0
        self.excess_N = 2.0 * self.adhesion_N * r / (1.0 + r) * gain

    def advance(
        self, h_s: float, v_m_s: float, fn_N: float, mu_s: float, mu_k: float
    ) -> float:
        """Advance ``h_s`` seconds at object speed ``v_m_s`` and per-nib load ``fn_N``; ``u`` (m)."""
        w0, k_l = self.w0, self.k_l
        v = float(v_m_s)
        r = float(h_s)
        # Each pass ends the interval, a stick or a slip (a slip from a breakaway lasts
        # at least pi / w0): the bound only guards against a non-finite input.
        for _ in range(100_000):
            if r <= 0.0:
                break
            if self.stuck:
                self.w_m_s = v
                if v <= 0.0:
                    break  # the object is at rest: the stuck nib keeps its deflection
                gap = (mu_s * fn_N + self.excess_N) / k_l - self.u_m
                if gap > v * r:
                    self.u_m += v * r
                    break
                tb = max(gap, 0.0) / v
                self.u_m += v * tb
                r -= tb
                self.stuck = False
                continue
            # Slip: u(s) = c + A cos(w0 s) + (w / w0) sin(w0 s), u'(s) = R cos(w0 s + psi).
            c = mu_k * fn_N / k_l
            a = self.u_m - c
            w = self.w_m_s
            big_r = math.hypot(a * w0, w)
            psi = math.atan2(a * w0, w)
            s_end = math.inf
            if big_r > 0.0 and abs(v) <= big_r:
                # Upward crossing of u' = v: cos(theta) = v / R with sin(theta) < 0.
                theta = _TWO_PI - math.acos(v / big_r)
                s_end = ((theta - psi) % _TWO_PI) / w0
                if s_end <= 1e-15:
                    s_end += _TWO_PI / w0
            s = min(s_end, r)
            self.u_m = c + a * math.cos(w0 * s) + (w / w0) * math.sin(w0 * s)
            self.w_m_s = big_r * math.cos(w0 * s + psi)
            r -= s
            if s_end <= s:
                self.stuck = True
                self.w_m_s = v
                self._draw_excess(v)
        return self.u_m


@dataclass(frozen=True)
class _Grip:
    """The plant's grip seen by ``gross_deflection``: the axial deflection now (m)."""

    x_m: float
    start_s: float = math.nan

    def axial_deflection(self, t: np.ndarray) -> np.ndarray:
        """``x - x0`` at every ``t`` (m): the plant's current value."""
        return np.full(np.shape(t), self.x_m, dtype=np.float64)


class SlipTackSensor:
    """The nib signal of one frame from the plant's state, by the effects the scene lists.

    ``stick_slip`` is stepped by :class:`NibOscillator` with the plant's current slip
    speed and per-nib load (grip force / ``nib_count``); ``gross_deflection`` and
    ``white_noise`` are the scene's effect functions called on a one-frame state
    (effect parameters drawn per trial as ``Scene.run_trial`` does). Any other listed
    effect is refused by name (``nib_harmonics`` needs the next breakaway, which a
    causal loop does not know).

    Parameters
    ----------
    scene : Scene
        A ``sliptack_pull`` or ``sliptack_drop`` scene.
    material : mapping
        The trial's friction row (``mu_s``, ``mu_k``, adhesion terms).
    rng : numpy.random.Generator
        The trial's generator.
    nib_count : float
        Nibs sharing the grip force.
    """

    def __init__(
        self,
        scene: Scene,
        material: Mapping[str, float],
        rng: np.random.Generator,
        *,
        nib_count: float,
    ) -> None:
        self.scene_name = scene.name
        self.keys = scene.effect_keys()
        known = FRAME_EFFECTS | RECURSIVE_EFFECTS
        unknown = [k for k in self.keys if effect_name(k) not in known]
        if unknown:
            raise SlipkitError(
                f"configs/scene/{scene.name}.yaml effects {unknown}: cannot be evaluated "
                f"one frame at a time by the closed loop; it knows {sorted(known)}"
            )
        self.params: dict[str, dict[str, Any]] = {}
        for key in self.keys:
            kwargs, _ = draw_effect_params(key, scene.effects[key], rng)
            self.params[key] = kwargs
        self.rng = rng
        self.mu_s = float(material["mu_s"])
        self.mu_k = float(material["mu_k"])
        self.nib_count = float(nib_count)
        self.nibs: dict[str, NibOscillator] = {}
        for key in self.keys:
            if effect_name(key) in RECURSIVE_EFFECTS:
                p = self.params[key]
                self.nibs[key] = NibOscillator(
                    M_kg=float(p["M_kg"]),
                    k_l_N_m=float(p["k_l_N_m"]),
                    adhesion=material,
                    rng=rng,
                )
        self._t = math.nan

    def frame(self, state: PlantState) -> np.ndarray:
        """The nib signal for ``state``, shape (1,), mm."""
        h = 0.0 if math.isnan(self._t) else max(state.t - self._t, 0.0)
        self._t = state.t
        v = state.speed_mm_s * 1e-3 if state.sliding else 0.0
        fn = state.normal_N / self.nib_count
        one = SceneState(
            time={"nib": np.array([state.t])},
            signals={"nib": np.zeros(1)},
            truth={"motion": _Grip(state.indentation_mm * 1e-3)},
        )
        for key in self.keys:
            name = effect_name(key)
            if name in RECURSIVE_EFFECTS:
                u = self.nibs[key].advance(h, v, fn, self.mu_s, self.mu_k)
                target = str(self.params[key].get("target", "nib"))
                one = one.with_signal(target, one.signals[target] + 1e3 * u)
                continue
            one = EFFECTS[name](one, self.rng, **self.params[key])
        return np.asarray(one.signals["nib"], dtype=np.float64)


class SlipTackPlant(SteppedPlant):
    """A parallel-jaw grip on an object loaded along the contact (module docstring).

    Parameters
    ----------
    mode : {"drop", "pull"}
        Gravity drop after a release, or a force-limited pull at a constant speed.
    mass_kg : float
        Object mass, kg (the drop's load ``m g``).
    mu_s, mu_k : float
        Static and kinetic friction coefficients.
    k_a_N_mm : float
        Axial stiffness of the grip: ``N = k_a x``, N/mm.
    grip_mm : float
        Axial deflection while gripped, mm.
    open_mm : float
        Drop: the deflection the opened fingers relax to, mm (pull: ``grip_mm``).
    release_s : float
        Drop: the fingers open; pull: the string goes taut, s.
    opening_tau_s : float
        Time constant of the fingers' opening, s.
    load_N : float
        Pull: the string's tension, N (drop: ignored, the load is ``m g``).
    pull_speed_mm_s : float
        Pull: the sliding speed, mm/s.
    regrasp_mm : float
        Deflection the regrasp closes the fingers to, mm.
    close_tau_s : float
        Time constant of the closing, s.
    read_s, motor_s : float
        After a declared slip: signal read before acting, motor response time, s.
    travel_mm : float
        Slide past which the object is lost, mm.
    rate_hz : float
        Frame rate, Hz.
    substeps : int
        Integration steps per frame.
    """

    def __init__(
        self,
        *,
        mode: str,
        mass_kg: float,
        mu_s: float,
        mu_k: float,
        k_a_N_mm: float,
        grip_mm: float,
        open_mm: float,
        release_s: float,
        opening_tau_s: float,
        load_N: float = 0.0,
        pull_speed_mm_s: float = 0.0,
        regrasp_mm: float,
        close_tau_s: float,
        read_s: float,
        motor_s: float,
        travel_mm: float,
        rate_hz: float,
        substeps: int = 4,
    ) -> None:
        if mode not in ("drop", "pull"):
            raise SlipkitError(f"mode: expected 'drop' or 'pull'; got {mode!r}")
        self.mode = mode
        self.mass_kg = float(mass_kg)
        self.mu_s, self.mu_k = float(mu_s), float(mu_k)
        self.k_a = float(k_a_N_mm)
        self.grip_mm, self.open_mm = float(grip_mm), float(open_mm)
        self.release_s = float(release_s)
        self.opening_tau_s = float(opening_tau_s)
        self.pull_load_N = float(load_N)
        self.pull_speed = float(pull_speed_mm_s)
        self.regrasp_mm = float(regrasp_mm)
        self.close_tau_s = float(close_tau_s)
        self.read_s, self.motor_s = float(read_s), float(motor_s)
        self.travel_mm = float(travel_mm)
        self.rate_hz = float(rate_hz)
        self.substeps = int(substeps)
        self.closing_s = math.inf  # when the fingers start closing (regrasp)
        self.state = PlantState(
            t=0.0,
            indentation_mm=self.grip_mm,
            arm_mm_s=0.0,
            normal_N=self.k_a * self.grip_mm,
        )

    def load(self, t: float) -> float:
        """Tangential load on the object at ``t``, N."""
        if self.mode == "drop":
            return self.mass_kg * G_M_S2
        return self.pull_load_N if t >= self.release_s else 0.0

    def open_loop_grip(self, t: float) -> float:
        """The fingers' deflection without any regrasp, mm."""
        if t < self.release_s:
            return self.grip_mm
        decay = math.exp(-(t - self.release_s) / self.opening_tau_s)
        return self.open_mm + (self.grip_mm - self.open_mm) * decay

    def open_loop_onset(self) -> float:
        """When the object would start to slip without a regrasp, s (inf: never)."""
        if self.mode == "pull":
            return (
                self.release_s
                if self.pull_load_N > self.mu_s * self.k_a * self.grip_mm
                else math.inf
            )
        x_b = self.mass_kg * G_M_S2 / (self.mu_s * self.k_a)
        if x_b >= self.grip_mm:
            return 0.0
        if self.open_mm >= x_b:
            return math.inf
        return self.release_s + self.opening_tau_s * math.log(
            (self.grip_mm - self.open_mm) / (x_b - self.open_mm)
        )

    def regrasp(self, t: float) -> None:
        """A slip declared at ``t``: the fingers start closing ``read_s + motor_s`` later."""
        if math.isinf(self.closing_s):
            self.closing_s = float(t) + self.read_s + self.motor_s

    def _substep(self, h: float) -> None:
        s = self.state
        t_next = s.t + h
        if s.t >= self.closing_s:
            target, tau = self.regrasp_mm, self.close_tau_s
        elif s.t >= self.release_s:
            target, tau = self.open_mm, self.opening_tau_s
        else:
            target, tau = self.grip_mm, self.opening_tau_s
        x_old = s.indentation_mm
        x = target + (x_old - target) * math.exp(-h / tau) if tau > 0 else target
        s.indentation_mm = x
        s.arm_mm_s = (x - x_old) / h
        s.normal_N = self.k_a * x
        q = self.load(t_next)
        s.load_N = q
        if not s.sliding and q > self.mu_s * s.normal_N:
            s.sliding = True
            s.slide_start_s = t_next  # what the oracle times its delay from
            if math.isnan(s.onset_s):
                s.onset_s = t_next
        if s.sliding:
            if self.mode == "pull":
                # A force-limited pull: it moves the object while it beats kinetic friction.
                if q <= self.mu_k * s.normal_N:
                    self._stick(t_next)
                else:
                    s.speed_mm_s = self.pull_speed
            else:
                # m a = m g - mu_k N (eq. 4), N / kg -> x 1e3 for mm/s^2; semi-implicit.
                accel = 1e3 * (q - self.mu_k * s.normal_N) / self.mass_kg
                speed = s.speed_mm_s + accel * h
                if speed <= 0.0 and q <= self.mu_s * s.normal_N:
                    self._stick(t_next)
                else:
                    s.speed_mm_s = max(speed, 0.0)
            s.drop_mm += s.speed_mm_s * h
            if s.drop_mm > self.travel_mm:
                s.dropped = True
        s.t = t_next


#: Declared ranges of the SlipTack plant's parameters (configs/closedloop/sliptack.yaml says the same).
PLANT_RULES = {
    "read_s": within(0.0, 1.0, "s"),
    "motor_s": within(0.0, 1.0, "s"),
    "close_tau_s": LAG_S,
    "regrasp_mm": within(0.0, 50.0, "mm", above=True),
    "onset_s": within(0.0, 10.0, "s", span=True),
    "post_s": within(0.0, 10.0, "s", above=True),
    "drop_travel_mm": TRAVEL_MM,
    "pull_travel_mm": TRAVEL_MM,
    "pull_load_ratio": within(1.0, 10.0, above=True, span=True),
    "nib_count": within(0.0, 10_000.0, above=True),
    "substeps": SUBSTEPS,
}
#: pull speeds of the conditions grid, mm/s
PULL_MM_S = within(0.0, 1000.0, "mm/s", above=True)


def check_plant(plant: Mapping[str, Any]) -> None:
    """Refuse SlipTack plant parameters outside their declared ranges (names the field)."""
    check_params(plant, PLANT_RULES, optional=("substeps",))


def run_sliptack_trial(
    scenes: Mapping[str, Scene],
    detector: Detector,
    plant_cfg: Mapping[str, Any],
    *,
    seed: int,
    condition_index: int,
    trial: int,
    condition: float,
) -> Outcome:
    """One SlipTack trial with ``detector`` in the loop: a pull (``condition`` > 0, mm/s) or the drop (0).

    Parameters
    ----------
    scenes : mapping
        ``"drop"`` and ``"pull"``: the ``sliptack_drop`` and ``sliptack_pull`` scenes
        (the model draws the trial; the effects make the nib signal).
    detector : Detector
        Decides per frame.
    plant_cfg : mapping
        ``read_s``, ``motor_s``, ``close_tau_s`` (s), ``regrasp_mm`` (mm), ``onset_s``
        (``[lo, hi]``: release / pull start, s), ``post_s`` (s simulated after the
        open-loop onset at most), ``drop_travel_mm``, ``pull_travel_mm`` (mm),
        ``pull_load_ratio`` (``[lo, hi]``: string tension over the grip's static
        friction), ``nib_count``, ``substeps``.
    seed, condition_index, trial : int
        The draw (``default_rng([seed, condition_index, trial])``).
    condition : float
        Pull speed, mm/s; 0 for the drop.
    """
    rng = np.random.default_rng([int(seed), int(condition_index), int(trial)])
    lo, hi = span(plant_cfg["onset_s"])
    common: dict[str, Any] = {
        "regrasp_mm": float(plant_cfg["regrasp_mm"]),
        "close_tau_s": float(plant_cfg["close_tau_s"]),
        "read_s": float(plant_cfg["read_s"]),
        "motor_s": float(plant_cfg["motor_s"]),
        "substeps": int(plant_cfg.get("substeps", 4)),
    }
    drop_model = scenes["drop"].model
    assert isinstance(drop_model, SlipTackDrop)
    k_a = drop_model.k_a_N_m * 1e-3  # N/mm
    if condition > 0:
        scene = scenes["pull"]
        model = scene.model
        assert isinstance(model, SlipTackPull)
        params = model.sample(rng)
        row = model.friction[str(params["material"])]
        nib_count = float(plant_cfg["nib_count"])
        grip_mm = float(params["normal_force_N"]) * nib_count / k_a
        ratio = float(rng.uniform(*span(plant_cfg["pull_load_ratio"])))
        release = float(rng.uniform(lo, hi))
        plant = SlipTackPlant(
            mode="pull",
            mass_kg=drop_model.mass_kg,
            mu_s=row["mu_s"],
            mu_k=row["mu_k"],
            k_a_N_mm=k_a,
            grip_mm=grip_mm,
            open_mm=grip_mm,
            release_s=release,
            opening_tau_s=drop_model.opening_time_s,
            load_N=ratio * row["mu_s"] * k_a * grip_mm,
            pull_speed_mm_s=float(condition),
            travel_mm=float(plant_cfg["pull_travel_mm"]),
            rate_hz=model.rate_hz,
            **common,
        )
        mass = math.nan  # a driven pull: the mass plays no part
        label = f"pull:{params['material']}"
    else:
        scene = scenes["drop"]
        model = drop_model
        params = model.sample(rng)
        row = model.friction[str(params["material"])]
        nib_count = model.nib_count
        release = float(rng.uniform(lo, hi))
        plant = SlipTackPlant(
            mode="drop",
            mass_kg=model.mass_kg,
            mu_s=row["mu_s"],
            mu_k=row["mu_k"],
            k_a_N_mm=k_a,
            grip_mm=model.hold_deflection_mm,
            open_mm=float(params["slide_deflection_mm"]),
            release_s=release,
            opening_tau_s=model.opening_time_s,
            travel_mm=float(plant_cfg["drop_travel_mm"]),
            rate_hz=model.rate_hz,
            **common,
        )
        mass = model.mass_kg
        label = f"drop:{params['material']}"
    sensor = SlipTackSensor(scene, row, rng, nib_count=nib_count)
    detector.reset()
    dt = 1.0 / plant.rate_hz
    onset_ol = plant.open_loop_onset()
    t_end = (onset_ol if math.isfinite(onset_ol) else release) + float(
        plant_cfg["post_s"]
    )
    declared = math.nan
    frames = 0
    peak, impulse = 0.0, 0.0
    state = plant.state
    while state.t < t_end and not state.dropped:
        if math.isnan(declared):
            frames += 1
            if detector.decide(state, partial(sensor.frame, state)):
                declared = state.t
                plant.regrasp(state.t)
        else:
            slipped = not math.isnan(state.onset_s)
            if slipped and not state.sliding:
                break  # arrested
            if not slipped and state.t >= onset_ol:
                break  # a false alarm held the object past its open-loop onset
            if not slipped:
                extra = state.normal_N - plant.k_a * plant.open_loop_grip(state.t)
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
    return Outcome(
        detector=detector.name,
        seed=int(seed),
        condition_index=int(condition_index),
        trial=int(trial),
        condition=float(condition),
        mass_kg=float(mass),
        object=label,
        onset_s=onset,
        declared_s=declared,
        false_alarm=bool(false_alarm),
        delay_ms=delay,
        arrest_s=state.arrest_s,
        slip_mm=plant.travel_mm if dropped else float(state.drop_mm),
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


@register_scenario("sliptack")
class SlipTackScenario(GridScenario):
    """SlipTack pull (speeds from ``pull_speeds``) and drop (condition 0), regrasp on slip."""

    condition_label = "pull speed (mm/s); 0: the drop"
    family = "SlipTack"
    scene_class = SlipTackDrop
    scene_title = "a SlipTack drop scene"
    grid_key = "pull_speeds"
    grid_rule = PULL_MM_S

    def check_plant(self, plant: Mapping[str, Any]) -> None:
        """Refuse plant parameters outside their declared ranges (:func:`check_plant`)."""
        check_plant(plant)

    def __init__(self) -> None:
        self.scenes: dict[str, Scene] = {}

    def check(self, scen: DictConfig, scene: Scene) -> None:
        """Refuse bad plant parameters; the drop scene is ``scene``, the pull scene ``pull_scene``."""
        from hydra import compose

        from slipkit.sim.commands import build_scene

        super().check(scen, scene)
        assert isinstance(scene.model, SlipTackDrop)
        pull_cfg = compose(
            config_name="train", overrides=[f"scene={scen.pull_scene}"]
        ).scene
        pull = build_scene(pull_cfg)
        if not isinstance(pull.model, SlipTackPull):
            raise SlipkitError(
                f"closedloop.pull_scene: needs a SlipTack pull scene; got "
                f"{type(pull.model).__name__}"
            )
        if pull.model.rate_hz != scene.model.rate_hz:
            raise SlipkitError(
                f"closedloop.pull_scene: the pull and drop scenes must run at one rate; "
                f"got {pull.model.rate_hz} and {scene.model.rate_hz} Hz"
            )
        self.scenes = {"drop": scene, "pull": pull}

    def conditions(self, scen: DictConfig) -> list[float]:
        """``pull_speeds.n`` log-spaced pull speeds (mm/s), then 0 (the drop) if ``drop``."""
        sp = dict(scen.pull_speeds)
        check_params(
            sp, {"n": within(0, 100, whole_number=True)}, "closedloop.pull_speeds"
        )
        out = (
            speed_grid(*check_grid(sp, "closedloop.pull_speeds", PULL_MM_S))
            if sp["n"]
            else []
        )
        if bool(scen.get("drop", True)):
            out = [*out, 0.0]
        if not out:
            raise SlipkitError(
                "closedloop.pull_speeds.n=0 and closedloop.drop=false: no condition to run"
            )
        return out

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
        """One trial (:func:`run_sliptack_trial`)."""
        scenes = {**self.scenes, "drop": scene}
        if "pull" not in scenes:
            raise SlipkitError("closedloop: SlipTackScenario.check was not run")
        return run_sliptack_trial(
            scenes,
            detector,
            plant,
            seed=seed,
            condition_index=condition_index,
            trial=trial,
            condition=condition,
        )
