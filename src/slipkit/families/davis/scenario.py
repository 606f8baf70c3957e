"""DAVIS closed loop: grasp lightly, lift, and catch the incipient slip the contact area shows.

Rigi et al. 2018 (Sensors 18(2):333) watch, with a DAVIS event camera under transparent
silicone, the contact patch of an object pressed, held and released; incipient slip is
"the earliest slight loss of the object contact area" (Sec. 3.2), its ground truth the
first 1000 FPS frame whose contact area is below the minimum of the constant-force
phase (Sec. 4.3); the detector's 10 ms event frames flag slip when the area that lost
contact (positive events) is at least the area that gained it. "Detection of incipient
slip facilitates the system to prevent slip by modifying the gripping force."

Here each trial: the scene model draws the object (contact-patch shape, centre,
orientation, the side that loses contact first) and the press and hold times
(:meth:`slipkit.families.davis.scene.DavisRelease.sample`); the hand presses the object
against the silicone (the grip ramps to ``F_hold``, the patch grows as ``F^(1/3)``, the
scene's press law), holds it, and lifts: the tangential load rises to the weight
``m g`` over the condition's time (a raised cosine). The grasp is light (its static
friction carries ``grip_ratio`` of the weight), so without a response the object
slides out. Before it slides, the shear shrinks the contact from one side: the patch
keeps the fraction ``1 - area_loss (tau / (mu_s F))^2`` of its Hertz ellipse
(``tau`` the tangential force on the contact), cut by a line across the scene's
release direction (the trailing side). The plant's incipient-slip onset is the
paper's: the first 1 ms step (the 1000 FPS truth camera) at which the contact covers
fewer pixel centres than during the hold (:class:`TruthArea`). Gross slip is
Coulomb's (:class:`~slipkit.closedloop.plant.PinchPlant`); the sliding object moves
the patch across the array. On a declared slip the controller raises the grip to
``catch_factor F_hold`` through an actuator's latency and first-order lag
(one-shot, like the TacTip catch: the detector is not consulted afterwards).

Sensor (:class:`DavisSensor`): the event frames the exported bundles read (counts per
pixel, positive then negative, over the detector's frame: 10 ms for the polarity
rule, 20 ms for the learned classifier). Events are the scene's effects, evaluated
by their own functions: ``contact_events`` on the pixels the plant's patch covers or
uncovers (crossing times interpolated between the plant's 1 ms steps, the truth
camera's rate), ``vibration_incidents`` and ``background_events`` on the trial's
timeline (the scene draws vibration only while pressing and holding); frames are
built by the deployer's :func:`slipkit.families.davis.deploy.davis_event_frames`.

Outcome: ``onset_s`` the incipient-slip onset; a declaration before it is a false
alarm; ``slip_mm`` the gross slide (0 when the grip rose before the object slid);
``arrest_s`` when the object is stuck again with its contact area back at the hold
value.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache, partial
from typing import Any

import numpy as np

from slipkit._options import within
from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.pinch import load_profile
from slipkit.closedloop.plant import G_M_S2, Actuator, PinchPlant, PlantState
from slipkit.closedloop.run import Outcome
from slipkit.closedloop.scenarios import _draw, _span, register_scenario
from slipkit.closedloop.skeleton import GridScenario
from slipkit.errors import SlipkitError
from slipkit.families.davis.physics import ContactPatch
from slipkit.families.davis.scene import DavisRelease
from slipkit.sim.core import EFFECTS, Scene, SceneState, draw_effect_params, effect_name

#: Effects driven by the plant's contact patch, evaluated on each frame's crossings.
PLANT_EFFECTS = frozenset({"contact_events"})
#: Effects on the trial's timeline (the scene draws them independently of the release).
TIMELINE_EFFECTS = frozenset({"vibration_incidents", "background_events"})


def kept_fraction(d: np.ndarray) -> np.ndarray:
    """Fraction of the unit disc with ``x <= d`` (``d`` in [-1, 1])."""
    d = np.clip(np.asarray(d, dtype=np.float64), -1.0, 1.0)
    return 1.0 - (np.arccos(d) - d * np.sqrt(1.0 - d * d)) / math.pi


# The cut's inverse has no closed form; kept_fraction is monotone, so a table and
# np.interp invert it (to ~1e-6 of the radius) for whole arrays at once, which a
# root finder per value would not.
_D_GRID = np.linspace(-1.0, 1.0, 8193)
_F_GRID = kept_fraction(_D_GRID)


def cut_for_fraction(kept: np.ndarray) -> np.ndarray:
    """The cut ``d`` (normalised, -1..1) that keeps ``kept`` of the unit disc."""
    return np.interp(np.asarray(kept, dtype=np.float64), _F_GRID, _D_GRID)


@lru_cache(maxsize=4)
def frame_channels(height_px: int, width_px: int) -> tuple[str, ...]:
    """The DAVIS bundles' channels in order: ``pos_<row>_<col>`` then ``neg_<row>_<col>``."""
    return tuple(
        f"{p}_{r}_{c}"
        for p in ("pos", "neg")
        for r in range(int(height_px))
        for c in range(int(width_px))
    )


@dataclass
class GripActuator(Actuator):
    """The hand's grip: the open-loop ``profile`` until a command takes effect, then the lag.

    Before any command is in effect the output is ``profile(t)`` (the press ramp and
    hold the arm executes); from ``command`` time plus ``latency_s`` it moves towards
    the command with the first-order lag, starting from the profile's value then.
    """

    profile: Callable[[float], float] = field(default=lambda t: 0.0)

    def advance(self, t: float, h: float) -> float:
        """The grip at ``t + h``, N."""
        if len(self._commands) < 2 or self._commands[1][0] > t + 1e-12:
            self.output = float(self.profile(t + h))
            return self.output
        return super().advance(t, h)


@dataclass(frozen=True)
class ContactModel:
    """The contact patch as a function of the grip ``F`` and the contact's tangential force ``tau``.

    Attributes
    ----------
    patch : ContactPatch
        The scene's patch of the trial: its ellipse (semi-axes ``a``, ``b`` px) is the
        contact at ``hold_N``; ``release_angle`` points to the side that loses contact.
    hold_N : float
        Grip of the hold, N.
    mu_s : float
        Static friction coefficient.
    area_loss : float
        Fraction of the contact lost when ``tau`` reaches ``mu_s F`` (0..1).
    """

    patch: ContactPatch
    hold_N: float
    mu_s: float
    area_loss: float

    @property
    def hold_area_px(self) -> float:
        """Contact area at the hold, px (the ellipse ``pi a b``)."""
        return math.pi * self.patch.a * self.patch.b

    def radius(self, force_N: np.ndarray) -> np.ndarray:
        """Normalised ellipse size ``(F / F_hold)^(1/3)`` (Hertz; 1 at the hold)."""
        return np.cbrt(
            np.clip(np.asarray(force_N, dtype=np.float64), 0.0, None) / self.hold_N
        )

    def kept(self, force_N: np.ndarray, tangential_N: np.ndarray) -> np.ndarray:
        """Fraction of the ellipse still in contact: ``1 - area_loss min(tau / (mu_s F), 1)^2``."""
        f = np.asarray(force_N, dtype=np.float64)
        tau = np.abs(np.nan_to_num(np.asarray(tangential_N, dtype=np.float64)))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(f > 0, np.clip(tau / (self.mu_s * f), 0.0, 1.0), 0.0)
        return 1.0 - self.area_loss * ratio**2

    def area_ratio(self, force_N: float, tangential_N: float) -> float:
        """Contact area over the hold's."""
        r = float(self.radius(np.asarray(force_N)))
        return r * r * float(self.kept(np.asarray(force_N), np.asarray(tangential_N)))

    def cover(
        self,
        force_N: np.ndarray,
        tangential_N: np.ndarray,
        slide_px: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Which pixel centres ``(x, y)`` the contact covers, per state (rows) and pixel (columns).

        A state is a grip ``F`` (N), a tangential force ``tau`` (N) and a slide (px):
        the Hertz ellipse of size :meth:`radius`, cut across the release direction so
        that :meth:`kept` of it stays in contact, its centre moved by the slide away
        from the side that loses contact. Returns the mask and a margin in the
        ellipse's normalised units (<= 0 inside) for interpolating crossing times.
        """
        p = self.patch
        f = np.atleast_1d(np.asarray(force_N, dtype=np.float64))
        r = self.radius(f)[:, None]
        d = cut_for_fraction(self.kept(f, np.atleast_1d(tangential_N)))[:, None]
        shift = np.atleast_1d(np.asarray(slide_px, dtype=np.float64))[:, None]
        xs = x[None, :] + math.cos(p.release_angle) * shift
        ys = y[None, :] + math.sin(p.release_angle) * shift
        u, v = p.normalised(xs, ys)
        q = p.projection(xs, ys) / p.q_max()
        margin = np.maximum(np.hypot(u, v) - r, q - d * r)
        return (margin <= 0.0) & (r > 0.0), margin


class TruthArea:
    """The ground-truth camera's contact area: pixel centres the contact covers (paper Sec. 4.3).

    Parameters
    ----------
    contact : ContactModel
        The trial's contact.
    width_px, height_px : int
        The array.
    max_radius : float
        Largest normalised size the contact reaches in the trial (the catch grip's).

    Attributes
    ----------
    hold_px : int
        Covered pixels at the hold (grip ``hold_N``, no shear, no slide): the minimum of
        the constant-force phase, against which the incipient-slip onset is found.
    """

    def __init__(
        self, contact: ContactModel, width_px: int, height_px: int, max_radius: float
    ) -> None:
        self.contact = contact
        x, y = contact.patch.bbox(
            max(max_radius, 1.0), 2.0, int(width_px), int(height_px)
        )
        self.x, self.y = x.astype(np.float64), y.astype(np.float64)
        self.hold_px = int(self.count(np.array([contact.hold_N]), np.zeros(1))[0])

    def count(
        self,
        force_N: np.ndarray,
        tangential_N: np.ndarray,
        slide_px: np.ndarray | None = None,
    ) -> np.ndarray:
        """Covered pixels per state (grip N, tangential force N, slide px)."""
        f = np.atleast_1d(np.asarray(force_N, dtype=np.float64))
        shift = np.zeros(len(f)) if slide_px is None else slide_px
        inside, _ = self.contact.cover(f, tangential_N, shift, self.x, self.y)
        counts: np.ndarray = inside.sum(axis=1)
        return counts

    def below_hold(self, force_N: float, tangential_N: float, slide_px: float) -> bool:
        """Whether the area is below its hold value (the paper's incipient slip)."""
        n = self.count(
            np.array([force_N]), np.array([tangential_N]), np.array([slide_px])
        )
        return bool(n[0] < self.hold_px)


class DavisSensor:
    """Event frames of the plant's contact patch and the scene's timeline events (module docstring).

    Parameters
    ----------
    scene : Scene
        A DAVIS release scene (its model and effects).
    rng : numpy.random.Generator
        The trial's generator.
    contact : ContactModel
        The trial's contact.
    timeline_patch : ContactPatch
        The patch the timeline effects see (press and hold of the open loop).
    duration_s : float
        Trial length, s.
    frame_s : float
        The detector's frame, s (the events of ``[t - frame_s, t)`` make the frame at ``t``).
    """

    def __init__(
        self,
        scene: Scene,
        rng: np.random.Generator,
        *,
        contact: ContactModel,
        timeline_patch: ContactPatch,
        duration_s: float,
        frame_s: float,
    ) -> None:
        model = scene.model
        assert isinstance(model, DavisRelease)
        self.model = model
        self.rng = rng
        self.contact = contact
        self.frame_s = float(frame_s)
        self.shape = (int(model.height_px), int(model.width_px))
        keys = scene.effect_keys()
        known = PLANT_EFFECTS | TIMELINE_EFFECTS
        unknown = [k for k in keys if effect_name(k) not in known]
        if unknown:
            raise SlipkitError(
                f"configs/scene/{scene.name}.yaml effects {unknown}: the DAVIS closed "
                f"loop cannot evaluate them from the plant; it knows {sorted(known)}"
            )
        params = {k: draw_effect_params(k, scene.effects[k], rng)[0] for k in keys}
        state = SceneState(
            time={"events": np.zeros(0)},
            signals={"events": np.zeros((0, 3), dtype=np.int64)},
            truth={
                "patch": timeline_patch,
                "sensor_shape": (int(model.width_px), int(model.height_px)),
                "duration_s": float(duration_s),
            },
        )
        for key in keys:
            if effect_name(key) in TIMELINE_EFFECTS:
                state = EFFECTS[effect_name(key)](state, rng, **params[key])
        #: Timeline events, sorted: times (s, on the event clock) and (x, y, polarity).
        self.timeline_t = self._clock(
            np.asarray(state.time["events"], dtype=np.float64)
        )
        self.timeline_ev = np.asarray(state.signals["events"]).reshape(-1, 3)
        self.plant_keys = [k for k in keys if effect_name(k) in PLANT_EFFECTS]
        self.plant_params = {k: params[k] for k in self.plant_keys}
        # The plant's history (one entry per plant step): time, grip, tangential force, slide.
        self._t: list[float] = []
        self._f: list[float] = []
        self._tau: list[float] = []
        self._slide: list[float] = []
        self._done = 0  # history entries whose crossings made events
        self._pending_t = np.zeros(0)
        self._pending_ev = np.zeros((0, 3), dtype=np.int64)

    def _clock(self, t: np.ndarray) -> np.ndarray:
        """Event times on the camera's clock (the scene's ``timestamp_resolution_s``)."""
        res = self.model.timestamp_resolution_s
        return np.round(t / res) * res if res > 0 else t

    def record(self, state: PlantState) -> None:
        """Keep the plant's state after a step (the sensor sees every step)."""
        self._t.append(float(state.t))
        self._f.append(float(state.normal_N))
        self._tau.append(float(state.tangential_N))
        self._slide.append(float(state.drop_mm))

    def _pixels(self, k: slice) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of the array the patch can touch over the history steps ``k``."""
        p = self.contact.patch
        slide = np.asarray(self._slide[k]) / self.model.pixel_mm
        lo, hi = float(slide.min()), float(slide.max())
        mid = 0.5 * (lo + hi)
        centre = dataclasses.replace(
            p,
            cx=p.cx - math.cos(p.release_angle) * mid,
            cy=p.cy - math.sin(p.release_angle) * mid,
        )
        scale = float(self.contact.radius(np.asarray(self._f[k])).max())
        return centre.bbox(scale, 2.0 + 0.5 * (hi - lo), self.shape[1], self.shape[0])

    def _generate(self) -> None:
        """Contact events of every crossing since the last call (the scene's ``contact_events``)."""
        n = len(self._t)
        if n - self._done < 1:
            return
        a = max(self._done - 1, 0)
        k = slice(a, n)
        self._done = n
        if n - a < 2:
            return
        x, y = self._pixels(k)
        inside, margin = self.contact.cover(
            np.asarray(self._f[k]),
            np.asarray(self._tau[k]),
            np.asarray(self._slide[k]) / self.model.pixel_mm,
            x.astype(np.float64),
            y.astype(np.float64),
        )
        step, pix = np.nonzero(inside[1:] != inside[:-1])
        if not len(step):
            return
        t = np.asarray(self._t[k])
        g0, g1 = margin[step, pix], margin[step + 1, pix]
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(g0 != g1, g0 / (g0 - g1), 1.0)
        when = t[step] + np.clip(frac, 0.0, 1.0) * (t[step + 1] - t[step])
        covers = inside[step + 1, pix]
        state = SceneState(
            time={"events": np.zeros(0)},
            signals={
                "events": np.zeros((0, 3), dtype=np.int64),
                "pixels": np.column_stack([x[pix], y[pix]]).astype(np.int64),
                "t_cover": np.where(covers, when, np.inf),
                "t_uncover": np.where(covers, np.inf, when),
            },
            truth={"patch": self.contact.patch},
        )
        for key in self.plant_keys:
            state = EFFECTS[effect_name(key)](state, self.rng, **self.plant_params[key])
        new_t = self._clock(np.asarray(state.time["events"], dtype=np.float64))
        new_ev = np.asarray(state.signals["events"]).reshape(-1, 3)
        self._pending_t = np.concatenate([self._pending_t, new_t])
        self._pending_ev = np.concatenate([self._pending_ev, new_ev])

    def events(self, t0: float, t1: float) -> np.ndarray:
        """Events ``(t, x, y, polarity)`` with ``t0 <= t < t1``, sorted by time.

        Contact events come from the plant's history up to its last recorded step
        (events a pixel's latency pushes past ``t1`` wait for the next frame).
        """
        self._generate()
        keep = self._pending_t >= t1
        sel = (self._pending_t >= t0) & ~keep
        a, b = np.searchsorted(self.timeline_t, [t0, t1], side="left")
        t = np.concatenate([self.timeline_t[a:b], self._pending_t[sel]])
        ev = np.concatenate([self.timeline_ev[a:b], self._pending_ev[sel]])
        self._pending_t, self._pending_ev = (
            self._pending_t[keep],
            self._pending_ev[keep],
        )
        order = np.argsort(t, kind="stable")
        return np.column_stack([t[order], ev[order].astype(np.float64)])

    def frame(
        self, state: PlantState, channels: tuple[str, ...] | None = None
    ) -> np.ndarray:
        """The event frame ending at ``state.t``: counts per pixel, ``(2, height, width)``.

        Built by the deployer's :func:`~slipkit.families.davis.deploy.davis_event_frames` (the
        frames the bundle was checked on): channel 0 positive, 1 negative.
        """
        from slipkit.families.davis.deploy import davis_event_frames

        del channels  # checked once per trial (check_frame)
        t1 = float(state.t)
        t0 = t1 - self.frame_s
        ev = self.events(t0, t1)
        ev[:, 0] -= t0
        frames, _ = davis_event_frames(
            ev, frame_s=self.frame_s, height_px=self.shape[0], width_px=self.shape[1]
        )
        out: np.ndarray = (
            frames.sum(axis=0) if len(frames) else np.zeros((2, *self.shape))
        )
        return out


def check_frame(
    detector: Detector, model: DavisRelease, scene_name: str, step_s: float
) -> None:
    """Refuse a detector whose frame is not the sensor's (channels, a frame of whole plant steps)."""
    if detector.channels is None:
        return
    want = frame_channels(model.height_px, model.width_px)
    got = tuple(detector.channels)
    if got != want:
        raise SlipkitError(
            f"closedloop.detectors.{detector.name}: its bundle reads {len(got)} channels, "
            f"the closed loop's configs/scene/{scene_name}.yaml makes event frames of "
            f"2 x {model.height_px} x {model.width_px} ({want[0]}..{want[-1]})"
        )
    rate = detector.rate_hz
    steps = (1.0 / float(rate)) / step_s if rate else 1.0  # None: every plant step
    if not (math.isfinite(steps) and steps >= 1 and abs(steps - round(steps)) < 1e-6):
        raise SlipkitError(
            f"closedloop.detectors.{detector.name}: its bundle reads frames at {rate!r} Hz; "
            f"the DAVIS closed loop needs a frame of whole {step_s * 1e3:g} ms plant steps "
            f"(configs/scene/{scene_name}.yaml truth_rate_hz)"
        )


_RANGES = {"mass_kg": "kg", "mu_s": "1", "grip_ratio": "1", "area_loss": "1"}
_POSITIVE = {
    "mu_kinetic_ratio": "1",
    "catch_factor": "1",
    "post_s": "s",
    "travel_mm": "mm",
}
_NON_NEGATIVE = {"latency_s": "s", "tau_s": "s"}


def check_plant(plant: Mapping[str, Any]) -> None:
    """Refuse plant parameters that cannot run (names the field)."""
    where = "configs/closedloop/davis.yaml plant"
    for key, unit in _RANGES.items():
        value = plant.get(key)
        try:
            lo, hi = _span(value)
        except (TypeError, ValueError, IndexError):
            lo = hi = math.nan
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
            raise SlipkitError(
                f"{where}.{key}: expected a number or [lo, hi] with 0 < lo <= hi ({unit}); "
                f"got {value!r}"
            )
    for key in ("area_loss", "grip_ratio", "mu_kinetic_ratio"):
        hi = _span(plant.get(key, math.nan))[1]
        if not hi <= 1:
            raise SlipkitError(f"{where}.{key}: must be <= 1; got {plant.get(key)!r}")
    for group, strict in ((_POSITIVE, True), (_NON_NEGATIVE, False)):
        for key, unit in group.items():
            value = plant.get(key)
            x = math.nan
            if isinstance(value, int | float) and not isinstance(value, bool):
                x = float(value)
            if not (math.isfinite(x) and (x > 0 if strict else x >= 0)):
                raise SlipkitError(
                    f"{where}.{key}: expected a finite number {'>' if strict else '>='} 0 "
                    f"({unit}); got {value!r}"
                )
    contacts = plant.get("contacts")
    if not (
        isinstance(contacts, int) and not isinstance(contacts, bool) and contacts >= 1
    ):
        raise SlipkitError(
            f"{where}.contacts: expected a whole number >= 1; got {contacts!r}"
        )


def press_profile(
    press_start: float, press_s: float, hold_N: float
) -> Callable[[float], float]:
    """The open-loop grip: 0, a linear ramp to ``hold_N`` over ``press_s``, then ``hold_N`` (N)."""

    def grip(t: float) -> float:
        return hold_N * min(max((t - press_start) / press_s, 0.0), 1.0)

    return grip


def run_davis_trial(
    scene: Scene,
    detector: Detector,
    plant_cfg: Mapping[str, Any],
    *,
    seed: int,
    condition_index: int,
    trial: int,
    condition: float,
) -> Outcome:
    """One press-hold-lift trial with ``detector`` in the loop (module docstring).

    ``condition``: the lift time, s (the load rises to the weight over it).
    """
    model = scene.model
    if not isinstance(model, DavisRelease):
        raise SlipkitError(
            f"closedloop.scene: the DAVIS closed loop needs a DAVIS release scene; got "
            f"{type(model).__name__}"
        )
    rng = np.random.default_rng([int(seed), int(condition_index), int(trial)])
    params = model.sample(rng)
    lift_s = float(condition)
    params["release_s"] = lift_s  # the scene's release phase is the lift here
    patch = model.patch(params)
    mass = _draw(rng, plant_cfg["mass_kg"])
    mu_s = _draw(rng, plant_cfg["mu_s"])
    mu_k = float(plant_cfg["mu_kinetic_ratio"]) * mu_s
    grip_ratio = _draw(rng, plant_cfg["grip_ratio"])
    area_loss = _draw(rng, plant_cfg["area_loss"])
    contacts = int(plant_cfg["contacts"])
    weight = mass * G_M_S2
    hold_N = grip_ratio * weight / (contacts * mu_s)
    catch_N = float(plant_cfg["catch_factor"]) * hold_N
    lift0 = patch.release_start
    t_end = lift0 + lift_s + float(plant_cfg["post_s"])
    step_s = 1.0 / model.truth_rate_hz
    contact = ContactModel(patch=patch, hold_N=hold_N, mu_s=mu_s, area_loss=area_loss)
    profile = press_profile(patch.press_start, patch.press_s, hold_N)
    load = load_profile(
        weight_N=weight,
        lift_s=(lift0, lift0 + lift_s),
        rise_s=(math.inf, math.inf),
        final_N=weight,
    )
    actuator = GripActuator(
        float(plant_cfg["latency_s"]), float(plant_cfg["tau_s"]), profile=profile
    )
    plant = PinchPlant(
        mass_kg=mass,
        mu_s=mu_s,
        mu_k=mu_k,
        contacts=contacts,
        load=load,
        actuator=actuator,
        max_force_N=max(catch_N, hold_N),
        travel_mm=float(plant_cfg["travel_mm"]),
        rate_hz=model.truth_rate_hz,
        substeps=1,
    )
    # The open loop's onset (the light grip held): when a correct detector's response
    # would have raised the grip anyway; a false alarm's extra grip counts up to it.
    truth = TruthArea(
        contact,
        model.width_px,
        model.height_px,
        float(contact.radius(np.asarray(max(catch_N, hold_N)))),
    )
    grid = np.arange(lift0, t_end + step_s, step_s)
    open_onset = _open_loop_onset(truth, grid, load, hold_N, contacts, t_end)
    check_frame(detector, model, scene.name, step_s)
    sensor = None
    period = math.inf
    if detector.channels is not None:
        period = 1.0 / float(detector.rate_hz or model.truth_rate_hz)
        sensor = DavisSensor(
            scene,
            rng,
            contact=contact,
            timeline_patch=patch,
            duration_s=t_end,
            frame_s=period,
        )
    detector.reset()
    s = plant.state
    if sensor is not None:
        sensor.record(s)
    view = PlantState(
        t=0.0, indentation_mm=math.nan, arm_mm_s=math.nan, normal_N=s.normal_N
    )
    onset = arrest = declared = math.nan
    frames = 0
    peak, impulse = 0.0, 0.0
    next_frame = period
    while s.t < t_end - 1e-12 and not s.dropped:
        slipping = not math.isnan(onset) and math.isnan(arrest)
        view.t, view.normal_N, view.drop_mm = s.t, s.normal_N, s.drop_mm
        view.speed_mm_s, view.load_N, view.tangential_N = (
            s.speed_mm_s,
            s.load_N,
            s.tangential_N,
        )
        view.sliding, view.onset_s, view.slide_start_s = slipping, onset, onset
        view.arrest_s, view.dropped = arrest, s.dropped
        if math.isnan(declared):
            due = sensor is None or s.t >= next_frame - 1e-9
            if due:
                if sensor is not None:
                    next_frame += period
                frames += 1
                frame = (
                    partial(sensor.frame, view, detector.channels)
                    if sensor is not None
                    else _no_frame
                )
                if detector.decide(view, frame):
                    declared = s.t
                    actuator.command(s.t, catch_N)
        else:
            if not math.isnan(arrest):
                break  # held again
            if math.isnan(onset):
                if s.t >= open_onset:
                    break  # a false alarm held the object past its open-loop onset
                extra = s.normal_N - profile(s.t)
                peak = max(peak, extra)
                impulse += max(extra, 0.0) * step_s
        s = plant.step()
        if sensor is not None and math.isnan(declared):
            sensor.record(s)
        if math.isnan(onset):
            if s.t >= lift0 - 1e-12 and truth.below_hold(
                s.normal_N, s.tangential_N, s.drop_mm / model.pixel_mm
            ):
                onset = s.t
        elif (
            math.isnan(arrest)
            and not s.sliding
            and contact.area_ratio(s.normal_N, s.tangential_N) >= 1.0
        ):
            arrest = s.t
    false_alarm = not math.isnan(declared) and (math.isnan(onset) or declared < onset)
    delay = (
        (declared - onset) * 1e3
        if not (math.isnan(declared) or math.isnan(onset) or false_alarm)
        else math.nan
    )
    travel = float(plant_cfg["travel_mm"])
    dropped = bool(s.dropped or s.sliding)
    return Outcome(
        detector=detector.name,
        seed=int(seed),
        condition_index=int(condition_index),
        trial=int(trial),
        condition=lift_s,
        mass_kg=float(mass),
        object=str(params["object"]),
        onset_s=onset,
        declared_s=declared,
        false_alarm=bool(false_alarm),
        delay_ms=delay,
        arrest_s=arrest,
        slip_mm=travel if dropped else float(s.drop_mm),
        dropped=dropped,
        onset_to_arrest_ms=(
            (arrest - onset) * 1e3 if not (dropped or math.isnan(arrest)) else math.nan
        ),
        extra_force_N=float(peak) if false_alarm else 0.0,
        extra_impulse_Ns=float(impulse) if false_alarm else 0.0,
        frames=frames,
    )


def _open_loop_onset(
    truth: TruthArea,
    grid: np.ndarray,
    load: Callable[[float], float],
    hold_N: float,
    contacts: int,
    t_end: float,
) -> float:
    """When the light grip held through the lift first shows an area below the hold's, s.

    The load rises monotonically over the lift, so the covered area falls
    monotonically until it is below the hold's: a bisection over the grid finds it.
    """
    if not len(grid):
        return t_end

    def below(i: int) -> bool:
        tau = load(float(grid[i])) / contacts
        return bool(truth.count(np.array([hold_N]), np.array([tau]))[0] < truth.hold_px)

    if not below(len(grid) - 1):
        return t_end
    lo, hi = -1, len(grid) - 1  # below(hi); not below(lo) (lo = -1: before the grid)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if below(mid):
            hi = mid
        else:
            lo = mid
    return float(grid[hi])


def _no_frame() -> np.ndarray:
    raise SlipkitError("closedloop: a detector without channels asked for a frame")


#: the lift time grid's range (``lift_s.lo``, ``lift_s.hi``)
LIFT_S = within(0.0, 10.0, "s", above=True)


@register_scenario("davis")
class DavisScenario(GridScenario):
    """The DAVIS press, hold and lift (module docstring); conditions: the lift time, s."""

    condition_label = "lift time (s)"
    family = "DAVIS"
    scene_class = DavisRelease
    scene_title = "a DAVIS release scene"
    grid_key = "lift_s"
    grid_rule = LIFT_S

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
        """One press-hold-lift trial (:func:`run_davis_trial`)."""
        return run_davis_trial(
            scene,
            detector,
            plant,
            seed=seed,
            condition_index=condition_index,
            trial=trial,
            condition=condition,
        )
