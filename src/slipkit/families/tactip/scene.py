"""TacTip gravity drop (James, Pestell, Lepora 2018, RA-L 3(4), Sec. III-A3 and IV-C).

An object hangs on a low-friction rail, held against a TacTip by friction. The arm
retracts at a constant speed, so the indentation and the grip force fall until
static friction no longer carries the weight: that instant is the slip onset.

The backbone holds the pins' rest layout plus the radial spreading that the
indentation causes in and around the contact patch, and the ground truth
(``truth_grip``: normal force, indentation, hold ratio, object drop). The skin's
pre-slip stretch, the snap-back at onset, post-slip sliding, detection jitter and
missing pins are effects (``slipkit.families.tactip.effects``); a scene has only those
it lists. See ``docs/families/tactip.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import LabelSpec, StreamSpec
from slipkit.families.tactip.physics import (
    contact_semi_axes,
    contact_weights,
    normal_force_N,
    object_radius_mm,
    pin_channels,
    pin_layout,
    slip_indentation_mm,
)
from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, sample_times

G_M_S2 = 9.81  # gravitational acceleration, m/s^2

TRUTH_CHANNELS = ("normal_force", "indentation", "hold_ratio", "object_drop")
TRUTH_UNITS = {
    "normal_force": "N",
    "indentation": "mm",
    "hold_ratio": "1",
    "object_drop": "mm",
}


def _range(key: str, value: Any, *, positive: bool = True) -> tuple[float, float]:
    """A config range: a number (fixed) or ``[lo, hi]``; raises naming ``key``."""
    return params.value_range(
        f"model.{key}", value, lo=0.0 if positive else None, strict_lo=True
    )


def _positive(key: str, value: float) -> float:
    return params.number(f"model.{key}", value, lo=0.0, strict_lo=True)


@dataclass(frozen=True)
class TacTipTrial:
    """One trial's physical parameters; effects evaluate the contact at any time.

    Attributes
    ----------
    rest_xy : ndarray (N, 2)
        Pin rest positions, mm.
    onset_s : float
        True slip onset, s (``μ_s F_n = m g``).
    retract_start_s : float
        When the arm starts retracting, s (negative: before the recording starts).
    speed_mm_s : float
        Retraction speed, mm/s.
    press_mm : float
        Indentation before the retraction, mm.
    stiffness : float
        Hertz normal stiffness ``K`` in ``F_n = K δ^1.5``, N/mm^1.5.
    weight_N, mu_s, mu_k : float
        Object weight (N) and static / kinetic friction coefficients.
    object_radius : float
        Stimulus radius of curvature, mm (inf: flat).
    tip_radius_mm, spread_mm : float
        TacTip dome radius and the skin's coupling length outside the contact, mm.
    stretch_mm : float
        Skin stretch at onset in the contact, mm (``m g / k_t``).
    radial_gain : float
        Radial pin spreading per mm of indentation, scaled by ``r / R_tip``.
    load_dir : ndarray (2,)
        Unit vector of gravity in the image (the direction the skin stretches).
    """

    rest_xy: np.ndarray
    onset_s: float
    retract_start_s: float
    speed_mm_s: float
    press_mm: float
    stiffness: float
    weight_N: float
    mu_s: float
    mu_k: float
    object_radius: float
    tip_radius_mm: float
    spread_mm: float
    stretch_mm: float
    radial_gain: float
    load_dir: np.ndarray

    def indentation(self, t: np.ndarray) -> np.ndarray:
        """Indentation δ(t) = press - v max(0, t - t_retract), clipped at 0 (mm)."""
        d = self.press_mm - self.speed_mm_s * np.clip(
            t - self.retract_start_s, 0.0, None
        )
        return np.clip(d, 0.0, None)

    def normal_force(self, t: np.ndarray) -> np.ndarray:
        """Grip force ``F_n = K δ(t)^1.5`` (N)."""
        return normal_force_N(self.indentation(t), self.stiffness)

    def load_ratio(self, t: np.ndarray) -> np.ndarray:
        """Tangential load over static friction capacity, ``m g / (μ_s F_n)`` (inf without contact)."""
        cap = self.mu_s * self.normal_force(t)
        return np.divide(
            self.weight_N, cap, out=np.full_like(cap, np.inf), where=cap > 0
        )

    def weights(self, t: np.ndarray) -> np.ndarray:
        """Contact weight of every pin at every time, shape (T, N) (see ``contact_weights``)."""
        ax, ay = contact_semi_axes(
            self.indentation(t), self.object_radius, self.tip_radius_mm
        )
        return contact_weights(self.rest_xy, ax, ay, self.spread_mm)


class TacTipGravityDrop:
    """Scene ``tactip_gravity_drop``: a held object slips as the TacTip retracts.

    Parameters (keyword-only, the keys of ``configs/scene/tactip_gravity_drop.yaml``)
    ----------
    rate_hz : float
        Camera frame rate, Hz (paper: 120 FPS).
    duration_s : float
        Trial length, s.
    onset_s : float or [lo, hi]
        Where the slip onset falls in the recording, s (uniform); the retraction
        start is placed so that the physics puts the onset there.
    n_pins, pitch_mm : int, float
        Pin count and spacing (mm) of the hexagonal grid (paper: 127 pins).
    tip_radius_mm : float
        Radius of the TacTip dome, mm.
    objects : list of str
        Stimuli, ``"flat"`` or ``"r<radius mm>"``; one drawn per trial (uniform).
    speed_mm_s : float or [lo, hi]
        Retraction speed, mm/s, drawn log-uniformly (paper: 0.1 to 20 mm/s).
    mass_kg : float or [lo, hi]
        Mass of object and slider, kg (uniform).
    mu_s, mu_k : float
        Static and kinetic friction coefficients (``0 <= mu_k <= mu_s``).
    contact_stiffness : float
        Hertz ``K`` in ``F_n = K δ^1.5``, N/mm^1.5.
    press_mm : float
        Indentation before the retraction, mm; must exceed the slip indentation.
    shear_stiffness_N_mm : float
        Tangential skin stiffness ``k_t``, N/mm: the stretch at onset is ``m g / k_t``.
    spread_mm : float
        Decay length of the skin's coupling outside the contact, mm.
    radial_gain : float
        Radial pin spreading: ``u_r = gain δ w r / R_tip`` (dimensionless gain).
    load_direction_deg : float
        Direction of gravity in the camera image, degrees from +x (-90: down).
    """

    sensor = "tactip"
    groups: tuple[str, ...] = ("object", "radius_mm", "speed_mm_s")

    def __init__(
        self,
        *,
        rate_hz: float = 120.0,
        duration_s: float = 3.0,
        onset_s: Any = (1.5, 2.5),
        n_pins: int = 127,
        pitch_mm: float = 3.0,
        tip_radius_mm: float = 20.0,
        objects: Sequence[str] = ("flat", "r20", "r40", "r80"),
        speed_mm_s: Any = (0.1, 20.0),
        mass_kg: Any = (0.05, 0.15),
        mu_s: float = 1.0,
        mu_k: float = 0.5,
        contact_stiffness: float = 0.5,
        press_mm: float = 3.0,
        shear_stiffness_N_mm: float = 1.0,
        spread_mm: float = 10.0,
        radial_gain: float = 0.3,
        load_direction_deg: float = -90.0,
    ) -> None:
        self.rate_hz = _positive("rate_hz", rate_hz)
        self.duration_s = _positive("duration_s", duration_s)
        self.onset_s = _range("onset_s", onset_s)
        frame = 1.0 / self.rate_hz
        if self.onset_s[0] < frame or self.onset_s[1] > self.duration_s - frame:
            raise SimulationError(
                f"model.onset_s: must lie within ({frame:.4g}, {self.duration_s - frame:.4g}) s "
                f"so the trial has frames before and after the onset; got {onset_s!r}"
            )
        if int(n_pins) != n_pins or n_pins < 1:
            raise SimulationError(
                f"model.n_pins: must be an integer >= 1; got {n_pins!r}"
            )
        self.n_pins = int(n_pins)
        self.pitch_mm = _positive("pitch_mm", pitch_mm)
        self.tip_radius_mm = _positive("tip_radius_mm", tip_radius_mm)
        self.objects = tuple(str(o) for o in objects)
        if not self.objects:
            raise SimulationError(
                "model.objects: list at least one stimulus ('flat', 'r20'...)"
            )
        try:
            self.radii = {o: object_radius_mm(o) for o in self.objects}
        except ValueError as exc:
            raise SimulationError(f"model.objects: {exc}") from exc
        self.speed_mm_s = _range("speed_mm_s", speed_mm_s)
        self.mass_kg = _range("mass_kg", mass_kg)
        self.mu_s = _positive("mu_s", mu_s)
        self.mu_k = float(mu_k)
        if not 0.0 <= self.mu_k <= self.mu_s:
            raise SimulationError(
                f"model.mu_k: need 0 <= mu_k <= mu_s ({self.mu_s}); got {mu_k!r}"
            )
        self.contact_stiffness = _positive("contact_stiffness", contact_stiffness)
        self.press_mm = _positive("press_mm", press_mm)
        heaviest = slip_indentation_mm(
            self.mass_kg[1] * G_M_S2, self.mu_s, self.contact_stiffness
        )
        if heaviest >= self.press_mm:
            raise SimulationError(
                f"model.press_mm: {self.press_mm} mm cannot hold a {self.mass_kg[1]} kg object "
                f"(slip indentation {heaviest:.3g} mm); raise press_mm or contact_stiffness"
            )
        self.shear_stiffness_N_mm = _positive(
            "shear_stiffness_N_mm", shear_stiffness_N_mm
        )
        self.spread_mm = _positive("spread_mm", spread_mm)
        self.radial_gain = float(radial_gain)
        if not (math.isfinite(self.radial_gain) and self.radial_gain >= 0):
            raise SimulationError(
                f"model.radial_gain: must be >= 0; got {radial_gain!r}"
            )
        self.load_direction_deg = float(load_direction_deg)
        if not math.isfinite(self.load_direction_deg):
            raise SimulationError(
                f"model.load_direction_deg: must be finite; got {load_direction_deg!r}"
            )
        self.rest_xy = pin_layout(self.n_pins, self.pitch_mm)
        self.channels = pin_channels(self.n_pins)

    def streams(self) -> dict[str, StreamSpec]:
        """``pins`` (2N channels, mm) and ``truth_grip`` (ground truth), both at the camera rate."""
        return {
            "pins": StreamSpec(
                "pins",
                self.channels,
                dict.fromkeys(self.channels, "mm"),
                rate_hz=self.rate_hz,
                description="TacTip pin centres: x0..x{N-1} then y0..y{N-1} in mm (NaN: pin not detected)",
            ),
            "truth_grip": StreamSpec(
                "truth_grip",
                TRUTH_CHANNELS,
                TRUTH_UNITS,
                rate_hz=self.rate_hz,
                description="ground truth: grip force, indentation, mu_s*F_n/(m g), object drop since onset",
            ),
        }

    def labels(self) -> dict[str, LabelSpec]:
        """``slip_onset_s``: when static friction stops holding the weight (s)."""
        return {"slip_onset_s": LabelSpec("slip_onset_s", unit="s")}

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """Draw the stimulus, retraction speed (log-uniform), mass and onset time."""
        obj = self.objects[int(rng.integers(len(self.objects)))]
        lo, hi = np.log(self.speed_mm_s)
        return {
            "object": obj,
            "radius_mm": self.radii[obj],
            "speed_mm_s": float(np.exp(rng.uniform(lo, hi))),
            "mass_kg": float(rng.uniform(*self.mass_kg)),
            "onset_s": float(rng.uniform(*self.onset_s)),
        }

    def trial(self, params: Mapping[str, Any]) -> TacTipTrial:
        """The physical parameters of one trial (the onset fixes the retraction start)."""
        weight = float(params["mass_kg"]) * G_M_S2
        d_slip = slip_indentation_mm(weight, self.mu_s, self.contact_stiffness)
        speed = float(params["speed_mm_s"])
        onset = float(params["onset_s"])
        angle = math.radians(self.load_direction_deg)
        return TacTipTrial(
            rest_xy=self.rest_xy,
            onset_s=onset,
            retract_start_s=onset - (self.press_mm - d_slip) / speed,
            speed_mm_s=speed,
            press_mm=self.press_mm,
            stiffness=self.contact_stiffness,
            weight_N=weight,
            mu_s=self.mu_s,
            mu_k=self.mu_k,
            object_radius=float(params["radius_mm"]),
            tip_radius_mm=self.tip_radius_mm,
            spread_mm=self.spread_mm,
            stretch_mm=weight / self.shear_stiffness_N_mm,
            radial_gain=self.radial_gain,
            load_dir=np.array([math.cos(angle), math.sin(angle)]),
        )

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        """Rest pins spread radially by the indentation; grip ground truth."""
        del rng  # the backbone is deterministic given the drawn parameters
        tr = self.trial(params)
        t = sample_times(self.duration_s, self.rate_hz)
        depth = tr.indentation(t)
        w = tr.weights(t)
        spread = (tr.radial_gain * depth / tr.tip_radius_mm)[:, None] * w
        pins = tr.rest_xy[None, :, :] * (1.0 + spread[..., None])
        force = tr.normal_force(t)
        # After the onset the object slides: m a = m g - μ_k F_n (semi-implicit Euler).
        dt = 1.0 / self.rate_hz
        accel = np.where(
            t >= tr.onset_s,
            G_M_S2 * np.clip(1.0 - tr.mu_k * force / tr.weight_N, 0.0, None),
            0.0,
        )
        drop_mm = 1e3 * np.cumsum(np.cumsum(accel) * dt) * dt
        hold = tr.mu_s * force / tr.weight_N
        truth = np.column_stack([force, depth, hold, drop_mm])
        return SceneState(
            time={"pins": t, "truth_grip": t.copy()},
            signals={"pins": pins, "truth_grip": truth},
            truth={
                "slip_onset_s": tr.onset_s,
                "tactip": tr,
                **{k: params[k] for k in self.groups},
            },
        )

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        """Pins as ``t, x0.., y0..`` (mm); ``truth_grip``; onset label; group values."""
        pins = np.asarray(state.signals["pins"])
        flat = np.concatenate([pins[..., 0], pins[..., 1]], axis=1)
        streams = {
            "pins": pd.DataFrame(
                np.column_stack([state.time["pins"], flat]),
                columns=["t", *self.channels],
            ),
            "truth_grip": pd.DataFrame(
                np.column_stack(
                    [state.time["truth_grip"], state.signals["truth_grip"]]
                ),
                columns=["t", *TRUTH_CHANNELS],
            ),
        }
        labels = {"slip_onset_s": float(state.truth["slip_onset_s"])}
        meta = {
            "object": str(state.truth["object"]),
            "radius_mm": float(state.truth["radius_mm"]),
            "speed_mm_s": float(state.truth["speed_mm_s"]),
        }
        return streams, labels, meta
