"""SlipTack scenes: a nib array dragged at constant speed, and a drop from a loosened grip.

``sliptack_pull`` follows the SlipTack paper's speed trials (Section IV-C: objects of
cherry, basswood and acrylic pulled at 10-100 mm/s across the sensor);
``sliptack_drop`` its acceleration trials (Section IV-D, eq. 4: a 283 g object released
from a parallel-jaw grip). The backbone holds the object's motion and the nib stream at
zero; the nib's response is added by the effects ``stick_slip`` and ``gross_deflection``
(:mod:`slipkit.families.sliptack.effects`). See ``docs/families/sliptack.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from slipkit.data.dataset import LabelSpec, StreamSpec
from slipkit.families.sliptack.physics import G_M_S2, ConstantSpeedMotion, FloatArray
from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, sample_times

Range = tuple[float, float]

#: Friction table keys a material may set, with their defaults.
MATERIAL_KEYS: dict[str, float] = {
    "mu_s": float("nan"),
    "mu_k": float("nan"),
    "adhesion_N": 0.0,
    "adhesion_cv": 0.0,
    "adhesion_exponent": 0.0,
    "adhesion_ref_speed_mm_s": 50.0,
}


def _number(value: Any, key: str) -> float:
    return params.number(key, value)


def _range(value: Any, key: str, lo: float = 0.0, strict: bool = True) -> Range:
    """A config number or ``[low, high]`` range, checked to lie above ``lo``."""
    return params.value_range(key, value, lo=lo, strict_lo=strict)


def _scalar(value: Any, key: str, lo: float = 0.0, strict: bool = True) -> float:
    return params.single(key, value, lo=lo, strict_lo=strict)


def _draw(rng: np.random.Generator, r: Range) -> float:
    return float(params.draw(rng, r))


def _materials(
    materials: Any, friction: Any, scene: str
) -> tuple[tuple[str, ...], dict[str, dict[str, float]]]:
    """Check the material list against the friction table (every key named on error)."""
    if (
        isinstance(materials, str)
        or not isinstance(materials, Sequence)
        or not materials
    ):
        raise SimulationError(
            f"{scene}: model.materials must be a non-empty list of names"
        )
    if not isinstance(friction, Mapping):
        raise SimulationError(
            f"{scene}: model.friction must map material -> coefficients"
        )
    names = tuple(str(m) for m in materials)
    table: dict[str, dict[str, float]] = {}
    for name in names:
        if name not in friction:
            raise SimulationError(
                f"{scene}: model.materials names {name!r}, which model.friction lacks; "
                f"friction has {sorted(map(str, friction))}"
            )
        entry = friction[name]
        if not isinstance(entry, Mapping):
            raise SimulationError(f"{scene}: model.friction.{name} must be a mapping")
        unknown = sorted(set(map(str, entry)) - set(MATERIAL_KEYS))
        if unknown:
            raise SimulationError(
                f"{scene}: model.friction.{name} has unknown keys {unknown}; "
                f"known: {sorted(MATERIAL_KEYS)}"
            )
        row = {
            k: _number(entry[k], f"model.friction.{name}.{k}") if k in entry else d
            for k, d in MATERIAL_KEYS.items()
        }
        key = f"{scene}: model.friction.{name}"
        if not 0.0 < row["mu_k"] < row["mu_s"]:
            raise SimulationError(
                f"{key}: need 0 < mu_k < mu_s; got mu_s={row['mu_s']}, mu_k={row['mu_k']}"
            )
        if (
            row["adhesion_N"] < 0
            or row["adhesion_cv"] < 0
            or row["adhesion_exponent"] < 0
        ):
            raise SimulationError(
                f"{key}: adhesion_N, adhesion_cv and adhesion_exponent must be >= 0"
            )
        if row["adhesion_ref_speed_mm_s"] <= 0:
            raise SimulationError(f"{key}.adhesion_ref_speed_mm_s must be > 0")
        table[name] = row
    return names, table


def _pick(rng: np.random.Generator, names: tuple[str, ...]) -> str:
    return names[int(rng.integers(len(names)))] if len(names) > 1 else names[0]


def _material_truth(row: Mapping[str, float]) -> dict[str, float]:
    return {k: float(v) for k, v in row.items()}


class SlipTackPull:
    """An unfeatured object pulled at constant speed across the nib array (speed trials).

    Phases: ``rest`` (``0 .. pull_start_s``, the string slack) then ``pull`` at
    ``speed_mm_s`` until ``duration_s``. The nib stream samples the coupled taxels'
    lateral nib deflection (mm) at ``rate_hz``: ~30 Hz for the individual mode, 500 Hz to
    2 kHz for the coupled modes. Ground truth: object position and speed.

    Parameters
    ----------
    rate_hz : float
        Nib stream sample rate (Hz).
    duration_s : float
        Trial length (s).
    pull_start_s : float
        When the string goes taut and the object moves at ``speed_mm_s`` (s).
    speed_mm_s : float or [low, high]
        Pull speed (mm/s), drawn per trial.
    normal_force_N : float or [low, high]
        Normal load on one nib (N), drawn per trial.
    materials : list of str
        Object materials, one drawn per trial.
    friction : mapping
        Per material: ``mu_s``, ``mu_k`` and optional adhesion terms (see
        :func:`slipkit.families.sliptack.effects.stick_slip`).
    """

    sensor = "sliptack"
    groups: tuple[str, ...] = ("material",)

    def __init__(
        self,
        *,
        rate_hz: float = 1000.0,
        duration_s: float = 2.2,
        pull_start_s: float = 0.2,
        speed_mm_s: Any = (10.0, 100.0),
        normal_force_N: Any = 0.05,
        materials: Any = ("cherry", "basswood", "acrylic"),
        friction: Any = None,
    ) -> None:
        scene = "sliptack_pull"
        self.rate_hz = _scalar(rate_hz, "model.rate_hz")
        self.duration_s = _scalar(duration_s, "model.duration_s")
        self.pull_start_s = _scalar(pull_start_s, "model.pull_start_s", strict=False)
        if self.pull_start_s >= self.duration_s:
            raise SimulationError(
                f"model.pull_start_s ({self.pull_start_s} s) must be < model.duration_s "
                f"({self.duration_s} s)"
            )
        if round(self.duration_s * self.rate_hz) < 2:
            raise SimulationError(
                "model.duration_s * model.rate_hz must give >= 2 samples"
            )
        self.speed_mm_s = _range(speed_mm_s, "model.speed_mm_s")
        self.normal_force_N = _range(normal_force_N, "model.normal_force_N")
        self.materials, self.friction = _materials(materials, friction or {}, scene)

    def streams(self) -> dict[str, StreamSpec]:
        """``nib`` (lateral deflection, mm) and ``truth_motion`` (position, speed)."""
        return {
            "nib": StreamSpec(
                "nib",
                ("deflection",),
                {"deflection": "mm"},
                rate_hz=self.rate_hz,
                description="coupled nib signal along the pull direction, as nib deflection",
            ),
            "truth_motion": StreamSpec(
                "truth_motion",
                ("position", "speed"),
                {"position": "mm", "speed": "mm/s"},
                rate_hz=self.rate_hz,
                description="ground truth: object displacement and speed",
            ),
        }

    def labels(self) -> dict[str, LabelSpec]:
        """Slip onset (pull start), pull speed and per-nib normal load."""
        return {
            "slip_onset_s": LabelSpec("slip_onset_s", unit="s"),
            "speed_mm_s": LabelSpec(
                "speed_mm_s", unit="mm/s", description="pull speed"
            ),
            "normal_force_N": LabelSpec(
                "normal_force_N", unit="N", description="normal load on one nib"
            ),
        }

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """Material, pull speed (mm/s) and per-nib normal load (N) of one trial."""
        return {
            "material": _pick(rng, self.materials),
            "speed_mm_s": _draw(rng, self.speed_mm_s),
            "normal_force_N": _draw(rng, self.normal_force_N),
        }

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        """The object's constant-speed pull; the nib stream at zero."""
        del rng  # the backbone is deterministic given the parameters
        t = sample_times(self.duration_s, self.rate_hz)
        motion = ConstantSpeedMotion(
            v0_m_s=float(params["speed_mm_s"]) * 1e-3,
            start_s=self.pull_start_s,
            normal_force_N=float(params["normal_force_N"]),
        )
        return SceneState(
            time={"nib": t, "truth_motion": t},
            signals={"nib": np.zeros_like(t)},
            truth={
                **params,
                **_material_truth(self.friction[str(params["material"])]),
                "motion": motion,
                "slip_onset_s": self.pull_start_s,
            },
        )

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        """Nib and ground-truth tables, labels and the material group."""
        motion: ConstantSpeedMotion = state.truth["motion"]
        tt = state.time["truth_motion"]
        streams = {
            "nib": pd.DataFrame(
                {"t": state.time["nib"], "deflection": state.signals["nib"]}
            ),
            "truth_motion": pd.DataFrame(
                {
                    "t": tt,
                    "position": 1e3 * motion.position(tt),
                    "speed": 1e3 * motion.speed(tt),
                }
            ),
        }
        labels = {
            "slip_onset_s": float(state.truth["slip_onset_s"]),
            "speed_mm_s": float(state.truth["speed_mm_s"]),
            "normal_force_N": float(state.truth["normal_force_N"]),
        }
        return streams, labels, {"material": str(state.truth["material"])}


@dataclass(frozen=True)
class DropMotion:
    """Object released from a loosened grip, sliding under gravity (SlipTack eq. 4).

    The gripper opens at ``release_s``: the axial nib deflection relaxes from ``hold_m``
    to ``slide_m`` as ``x(t) - x0 = slide + (hold - slide) exp(-(t - release) / tau)``.
    The object breaks away when ``mu_s k_a (x - x0) = m_t g`` (``start_s``; NaN if the
    grip still holds it) and then accelerates at ``a = g - mu_k k_a (x - x0) / m_t``
    (eq. 4), integrated in closed form for speed and position. The per-nib normal load
    is ``k_a (x - x0) / nib_count``.
    """

    release_s: float
    opening_time_s: float
    hold_m: float
    slide_m: float
    k_a_N_m: float
    mass_kg: float
    mu_s: float
    mu_k: float
    g_m_s2: float
    nib_count: float
    start_s: float

    @classmethod
    def build(
        cls,
        *,
        release_s: float,
        opening_time_s: float,
        hold_m: float,
        slide_m: float,
        k_a_N_m: float,
        mass_kg: float,
        mu_s: float,
        mu_k: float,
        g_m_s2: float,
        nib_count: float,
    ) -> DropMotion:
        """Compute the breakaway time from the grip and friction parameters."""
        x_b = (
            mass_kg * g_m_s2 / (mu_s * k_a_N_m)
        )  # deflection at which static friction fails
        if x_b >= hold_m:
            raise SimulationError(
                f"model.hold_deflection_mm ({hold_m * 1e3:.3g} mm) does not hold the object: "
                f"static friction fails below {x_b * 1e3:.3g} mm"
            )
        start = float("nan")
        if slide_m < x_b:
            start = release_s + opening_time_s * float(
                np.log((hold_m - slide_m) / (x_b - slide_m))
            )
        return cls(
            release_s,
            opening_time_s,
            hold_m,
            slide_m,
            k_a_N_m,
            mass_kg,
            mu_s,
            mu_k,
            g_m_s2,
            nib_count,
            start,
        )

    @property
    def _k(self) -> float:
        return self.mu_k * self.k_a_N_m / self.mass_kg

    def axial_deflection(self, t: ArrayLike) -> FloatArray:
        """Gross axial nib deflection ``x - x0`` (m)."""
        t = np.asarray(t, dtype=np.float64)
        decay = np.exp(-np.maximum(t - self.release_s, 0.0) / self.opening_time_s)
        return self.slide_m + (self.hold_m - self.slide_m) * decay

    def _since_start(self, t: ArrayLike) -> tuple[FloatArray, NDArray[np.bool_]]:
        t = np.asarray(t, dtype=np.float64)
        if not np.isfinite(self.start_s):
            return np.zeros_like(t), np.zeros(t.shape, dtype=bool)
        s = t - self.start_s
        return np.maximum(s, 0.0), s >= 0

    def acceleration(self, t: ArrayLike) -> FloatArray:
        """Eq. 4 after the breakaway, 0 before (m/s^2, downward positive)."""
        _, moving = self._since_start(t)
        a = self.g_m_s2 - self._k * self.axial_deflection(t)
        return np.where(moving, a, 0.0)

    def _terms(self, s: FloatArray) -> tuple[float, float, FloatArray]:
        a_inf = self.g_m_s2 - self._k * self.slide_m
        e_b = float(self.axial_deflection(self.start_s)) - self.slide_m
        return (
            a_inf,
            self._k * e_b * self.opening_time_s,
            -np.expm1(-s / self.opening_time_s),
        )

    def speed(self, t: ArrayLike) -> FloatArray:
        """Object speed (m/s): eq. 4 integrated from rest at the breakaway."""
        s, moving = self._since_start(t)
        if not moving.any():
            return np.zeros_like(s)
        a_inf, c, one_minus = self._terms(s)
        return np.where(moving, a_inf * s - c * one_minus, 0.0)

    def position(self, t: ArrayLike) -> FloatArray:
        """Object displacement (m, downward) since the breakaway."""
        s, moving = self._since_start(t)
        if not moving.any():
            return np.zeros_like(s)
        a_inf, c, one_minus = self._terms(s)
        return np.where(
            moving, 0.5 * a_inf * s * s - c * (s - self.opening_time_s * one_minus), 0.0
        )

    def nib_normal_force(self, t: ArrayLike) -> FloatArray:
        """Normal load on one nib, ``k_a (x - x0) / nib_count`` (N)."""
        return self.k_a_N_m * self.axial_deflection(t) / self.nib_count

    def state_at(self, t: float) -> tuple[float, float, float]:
        """Speed (m/s), acceleration (m/s^2) and per-nib load (N) at one time ``t`` (s)."""
        tau = self.opening_time_s
        dx = self.slide_m + (self.hold_m - self.slide_m) * math.exp(
            -max(t - self.release_s, 0.0) / tau
        )
        fn = self.k_a_N_m * dx / self.nib_count
        if not t >= self.start_s:  # also when start_s is NaN
            return 0.0, 0.0, fn
        s = t - self.start_s
        e_b = (self.hold_m - self.slide_m) * math.exp(
            -(self.start_s - self.release_s) / tau
        )
        one_minus = -math.expm1(-s / tau)
        a_inf = self.g_m_s2 - self._k * self.slide_m
        return (
            a_inf * s - self._k * e_b * tau * one_minus,
            self.g_m_s2 - self._k * dx,
            fn,
        )


class SlipTackDrop:
    """An object released from a loosened parallel-jaw grip slides down under gravity.

    Phases: ``hold`` (``0 .. release_s``, gripped at ``hold_deflection_mm``), ``release``
    (the fingers open with time constant ``opening_time_s`` to ``slide_deflection_mm``;
    the object breaks away when static friction fails), ``slide`` (eq. 4). Ground truth:
    position, speed, acceleration and axial deflection. The nib stream is zero in the
    backbone; ``gross_deflection`` and ``stick_slip`` add the gross deflection and the
    stick-slip oscillation.

    Parameters
    ----------
    rate_hz, duration_s : float
        Nib stream rate (Hz) and trial length (s).
    release_s : float
        When the gripper opens (s).
    opening_time_s : float
        Time constant of the axial deflection's relaxation as the fingers open (s).
    hold_deflection_mm : float
        Axial nib deflection ``x - x0`` while gripped (mm).
    slide_deflection_mm : float or [low, high]
        Axial deflection once open (mm), drawn per trial: sets the acceleration.
    k_a_N_m, mass_kg, g_m_s2 : float
        Axial surface stiffness (N/m), total object mass (kg), gravity (m/s^2).
    nib_count : float
        Nibs sharing the normal load (per-nib load = ``k_a (x - x0) / nib_count``).
    object_length_mm : float
        Length of the object; the trial must end before it can leave the grip.
    accel_window_delay_s, accel_window_travel_mm : float
        Window of the ``mean_acceleration_m_s2`` label: from this long after the release
        up to this travel (the paper: 0.06 s and 15 cm).
    materials, friction
        As in :class:`SlipTackPull`.
    """

    sensor = "sliptack"
    groups: tuple[str, ...] = ("material",)

    def __init__(
        self,
        *,
        rate_hz: float = 1000.0,
        duration_s: float = 0.6,
        release_s: float = 0.3,
        opening_time_s: float = 0.02,
        hold_deflection_mm: float = 3.0,
        slide_deflection_mm: Any = (0.9, 2.4),
        k_a_N_m: float = 2000.0,
        mass_kg: float = 0.283,
        g_m_s2: float = G_M_S2,
        nib_count: float = 60.0,
        object_length_mm: float = 500.0,
        accel_window_delay_s: float = 0.06,
        accel_window_travel_mm: float = 150.0,
        materials: Any = ("basswood",),
        friction: Any = None,
    ) -> None:
        scene = "sliptack_drop"
        self.rate_hz = _scalar(rate_hz, "model.rate_hz")
        self.duration_s = _scalar(duration_s, "model.duration_s")
        self.release_s = _scalar(release_s, "model.release_s", strict=False)
        self.opening_time_s = _scalar(opening_time_s, "model.opening_time_s")
        self.hold_deflection_mm = _scalar(
            hold_deflection_mm, "model.hold_deflection_mm"
        )
        self.slide_deflection_mm = _range(
            slide_deflection_mm, "model.slide_deflection_mm"
        )
        self.k_a_N_m = _scalar(k_a_N_m, "model.k_a_N_m")
        self.mass_kg = _scalar(mass_kg, "model.mass_kg")
        self.g_m_s2 = _scalar(g_m_s2, "model.g_m_s2")
        self.nib_count = _scalar(nib_count, "model.nib_count")
        self.object_length_mm = _scalar(object_length_mm, "model.object_length_mm")
        self.accel_window_delay_s = _scalar(
            accel_window_delay_s, "model.accel_window_delay_s", strict=False
        )
        self.accel_window_travel_mm = _scalar(
            accel_window_travel_mm, "model.accel_window_travel_mm"
        )
        self.materials, self.friction = _materials(materials, friction or {}, scene)
        if self.release_s >= self.duration_s:
            raise SimulationError("model.release_s must be < model.duration_s")
        if self.slide_deflection_mm[1] >= self.hold_deflection_mm:
            raise SimulationError(
                "model.slide_deflection_mm must stay below model.hold_deflection_mm "
                "(the fingers open)"
            )
        fall = 0.5 * self.g_m_s2 * (self.duration_s - self.release_s) ** 2 * 1e3
        if fall > self.object_length_mm:
            raise SimulationError(
                f"model.duration_s: a free fall after the release would travel {fall:.0f} mm, "
                f"more than model.object_length_mm ({self.object_length_mm:.0f} mm); "
                "shorten the trial so the object stays in the grip"
            )
        for name, row in self.friction.items():
            x_b = self.mass_kg * self.g_m_s2 / (row["mu_s"] * self.k_a_N_m) * 1e3
            if x_b >= self.hold_deflection_mm:
                raise SimulationError(
                    f"model.hold_deflection_mm ({self.hold_deflection_mm} mm) cannot hold a "
                    f"{name} object: static friction fails below {x_b:.3g} mm"
                )

    def streams(self) -> dict[str, StreamSpec]:
        """``nib`` (deflection, mm) and ``truth_motion`` (position, speed, acceleration, x - x0)."""
        return {
            "nib": StreamSpec(
                "nib",
                ("deflection",),
                {"deflection": "mm"},
                rate_hz=self.rate_hz,
                description="coupled nib signal along the sliding direction, as deflection",
            ),
            "truth_motion": StreamSpec(
                "truth_motion",
                ("position", "speed", "acceleration", "axial_deflection"),
                {
                    "position": "mm",
                    "speed": "mm/s",
                    "acceleration": "m/s^2",
                    "axial_deflection": "mm",
                },
                rate_hz=self.rate_hz,
                description="ground truth: downward object motion and axial nib deflection",
            ),
        }

    def labels(self) -> dict[str, LabelSpec]:
        """Breakaway time, release time and the windowed acceleration and deflection."""
        return {
            "slip_onset_s": LabelSpec("slip_onset_s", unit="s"),
            "release_s": LabelSpec("release_s", unit="s", description="gripper opens"),
            "mean_acceleration_m_s2": LabelSpec(
                "mean_acceleration_m_s2",
                unit="m/s^2",
                description="mean acceleration from release + delay up to the travel limit",
            ),
            "deflection_mm": LabelSpec(
                "deflection_mm",
                unit="mm",
                description="mean axial nib deflection x - x0 over the same window",
            ),
        }

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """Material and the opened grip's axial deflection (mm) of one trial."""
        return {
            "material": _pick(rng, self.materials),
            "slide_deflection_mm": _draw(rng, self.slide_deflection_mm),
        }

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        """The grip release and the object's eq.-4 slide; the nib stream at zero."""
        del rng
        row = self.friction[str(params["material"])]
        motion = DropMotion.build(
            release_s=self.release_s,
            opening_time_s=self.opening_time_s,
            hold_m=self.hold_deflection_mm * 1e-3,
            slide_m=float(params["slide_deflection_mm"]) * 1e-3,
            k_a_N_m=self.k_a_N_m,
            mass_kg=self.mass_kg,
            mu_s=row["mu_s"],
            mu_k=row["mu_k"],
            g_m_s2=self.g_m_s2,
            nib_count=self.nib_count,
        )
        t = sample_times(self.duration_s, self.rate_hz)
        return SceneState(
            time={"nib": t, "truth_motion": t},
            signals={"nib": np.zeros_like(t)},
            truth={
                **params,
                **_material_truth(row),
                "motion": motion,
                "slip_onset_s": motion.start_s,
                "release_s": self.release_s,
            },
        )

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        """Nib and ground-truth tables; labels over the paper's acceleration window."""
        motion: DropMotion = state.truth["motion"]
        tt = state.time["truth_motion"]
        pos = motion.position(tt)
        acc = motion.acceleration(tt)
        dx = motion.axial_deflection(tt)
        window = (
            (tt >= motion.start_s)
            & (tt >= self.release_s + self.accel_window_delay_s)
            & (pos <= self.accel_window_travel_mm * 1e-3)
        )
        has = bool(window.any())
        streams = {
            "nib": pd.DataFrame(
                {"t": state.time["nib"], "deflection": state.signals["nib"]}
            ),
            "truth_motion": pd.DataFrame(
                {
                    "t": tt,
                    "position": 1e3 * pos,
                    "speed": 1e3 * motion.speed(tt),
                    "acceleration": acc,
                    "axial_deflection": 1e3 * dx,
                }
            ),
        }
        labels = {
            "slip_onset_s": float(motion.start_s),
            "release_s": float(self.release_s),
            "mean_acceleration_m_s2": float(acc[window].mean())
            if has
            else float("nan"),
            "deflection_mm": float(1e3 * dx[window].mean()) if has else float("nan"),
        }
        return streams, labels, {"material": str(state.truth["material"])}
