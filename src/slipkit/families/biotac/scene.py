"""BioTac scenes after Su et al. 2015 (Humanoids): force-plate probe and lift-to-slip.

``biotac_force_probe`` (Sec. V-A): the finger pressed against a force plate from many
directions and places; electrodes at 300 Hz with force-plate ground truth.
``biotac_lift_slip`` (Sec. IV-B, IV-C, V-B, V-C): an object grasped at its centre of
mass (linear slip) or at an edge (rotational slip) and lifted until it slips;
electrodes at 300 Hz, AC pressure at 2.2 kHz, IMU-delayed reference onset.

The backbones here are linear and noiseless: electrodes follow ``E = A F``
(:func:`slipkit.families.biotac.physics.linear_drive_matrix`), for which the weighted-normals
estimate is exact; non-linearity, slip deformation, vibration and noise are effects
(:mod:`slipkit.families.biotac.effects`, :mod:`slipkit.sim.effects.common`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import LabelSpec, StreamSpec
from slipkit.families.biotac.physics import (
    CORE_RADIUS_MM,
    CYLINDER_LENGTH_MM,
    ELECTRODE_NAMES,
    cone_directions,
    linear_drive_matrix,
    surface_point,
    tangent_frame,
    weighted_normals_scales,
)
from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, phase_times, sample_times

SENSOR = "biotac"
GRAVITY_M_S2 = 9.81
#: Longest arc length on the core (mm): base to the cap's apex.
MAX_S_MM = CYLINDER_LENGTH_MM + 0.5 * np.pi * CORE_RADIUS_MM
SLIP_CLASSES: tuple[str, ...] = ("linear", "rotational")

#: The four objects of Su et al. 2015, Sec. V-C (wooden block, oil bottle, wipes box,
#: jar with added weights). Masses, friction and texture are assumptions: the paper
#: gives none of them (texture scales the slip micro-vibration; the block is "rough",
#: the jar "smooth", Sec. V-B).
DEFAULT_OBJECTS: dict[str, dict[str, float]] = {
    "wooden_block": {"mass_kg": 0.30, "mu_static": 1.2, "texture": 1.5},
    "oil_bottle": {"mass_kg": 0.50, "mu_static": 0.8, "texture": 0.8},
    "wipes_box": {"mass_kg": 0.25, "mu_static": 1.0, "texture": 1.0},
    "weighted_jar": {"mass_kg": 0.80, "mu_static": 0.7, "texture": 0.6},
}


def smooth_step(u: np.ndarray) -> np.ndarray:
    """Raised-cosine ramp from 0 (``u <= 0``) to 1 (``u >= 1``)."""
    return 0.5 * (1.0 - np.cos(np.pi * np.clip(u, 0.0, 1.0)))


def _scalar(
    key: str, value: Any, *, lo: float | None = None, strict: bool = True
) -> float:
    return params.number(key, value, lo=lo, strict_lo=strict)


def _range(
    key: str,
    value: Any,
    *,
    lo: float | None = None,
    hi: float | None = None,
    strict: bool = False,
) -> tuple[float, float]:
    """A ``[low, high]`` range (or one number, a fixed value) within ``[lo, hi]``."""
    return params.value_range(key, value, lo=lo, hi=hi, strict_lo=strict)


def _gain3(key: str, value: Any) -> tuple[float, float, float]:
    if isinstance(value, str) or not isinstance(value, Sequence):
        g = _scalar(key, value, lo=0.0)
        return g, g, g
    if len(value) != 3:
        raise SimulationError(f"{key} must be one number or 3 (x, y, z); got {value!r}")
    gx, gy, gz = (_scalar(key, v, lo=0.0) for v in value)
    return gx, gy, gz


def _draw(
    rng: np.random.Generator, r: tuple[float, float], size: int | None = None
) -> Any:
    # draws even a fixed range: the scene's random stream is laid out that way
    return params.draw(rng, r, size=size, skip_fixed=False)


def _frame(t: np.ndarray, **columns: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame({"t": t, **columns})


def _electrode_frame(t: np.ndarray, x: np.ndarray) -> pd.DataFrame:
    df = pd.DataFrame(x, columns=list(ELECTRODE_NAMES))
    df.insert(0, "t", t)
    return df


def _electrode_spec(rate_hz: float) -> StreamSpec:
    return StreamSpec(
        "electrodes",
        ELECTRODE_NAMES,
        dict.fromkeys(ELECTRODE_NAMES, "counts"),
        rate_hz=rate_hz,
        description="19 electrode impedances, ADC counts; counts rise with compression",
    )


class BioTacForceProbe:
    """The fingertip pressed on a force plate from many directions (Su et al. 2015,
    Sec. V-A, Fig. 5).

    A trial is a train of presses. Press ``k`` waits ``rest`` s, then its force rises
    and falls as ``|F| = F_k sin^2(pi u)`` over ``press`` s (``u`` from 0 to 1) while
    its direction turns from ``d0`` to ``d1``, both uniform (in solid angle) within
    ``cone_deg`` of the surface normal at the contact point ``(s, phi)``. Electrodes
    respond linearly, ``E = A F`` (exact weighted-normals); the DC pressure rises with
    the normal load.

    Parameters
    ----------
    rate_hz : float
        Electrode / force-plate sample rate (Hz); the paper's controller runs at 300.
    duration_s : float
        Trial length (s).
    press_s, rest_s : float or [low, high]
        Duration of each press and of the pause before it (s), drawn per press.
    force_N : float or [low, high]
        Peak force magnitude of each press (N).
    cone_deg : float
        Half-angle of the force-direction cone about the contact normal (deg), < 90.
    contact_s_mm : float or [low, high]
        Contact position along the core's meridian (mm from the base; the cap starts
        at 15 mm, the apex is at 24.4 mm).
    contact_phi_deg : float or [low, high]
        Contact azimuth about the finger axis from the pad's centre (deg).
    gain_counts_per_N : float or [x, y, z]
        Largest electrode sensitivity per force axis (counts/N).
    electrode_baseline_counts : float
        Unloaded electrode reading (counts).
    pdc_baseline_counts, pdc_gain_counts_per_N : float
        Unloaded DC pressure (counts) and its rise per newton of normal load.
    """

    sensor = SENSOR
    groups: tuple[str, ...] = ()

    def __init__(
        self,
        *,
        rate_hz: float = 300.0,
        duration_s: float = 60.0,
        press_s: Any = (0.8, 2.5),
        rest_s: Any = (0.1, 0.6),
        force_N: Any = (0.5, 10.0),
        cone_deg: float = 40.0,
        contact_s_mm: Any = (2.0, 22.0),
        contact_phi_deg: Any = (-45.0, 45.0),
        gain_counts_per_N: Any = 60.0,
        electrode_baseline_counts: float = 2000.0,
        pdc_baseline_counts: float = 2000.0,
        pdc_gain_counts_per_N: float = 30.0,
    ) -> None:
        self.rate_hz = _scalar("rate_hz", rate_hz, lo=0.0)
        self.duration_s = _scalar("duration_s", duration_s, lo=0.0)
        if round(self.duration_s * self.rate_hz) < 2:
            raise SimulationError(
                f"duration_s must hold >= 2 samples at rate_hz; got {duration_s}"
            )
        self.press_s = _range("press_s", press_s, lo=0.0, strict=True)
        self.rest_s = _range("rest_s", rest_s, lo=0.0)
        self.force_N = _range("force_N", force_N, lo=0.0)
        self.cone_deg = _scalar("cone_deg", cone_deg, lo=0.0, strict=False)
        if self.cone_deg >= 90.0:
            raise SimulationError(f"cone_deg must be < 90; got {cone_deg}")
        self.contact_s_mm = _range("contact_s_mm", contact_s_mm, lo=0.0, hi=MAX_S_MM)
        self.contact_phi_deg = _range(
            "contact_phi_deg", contact_phi_deg, lo=-180.0, hi=180.0
        )
        self.gain_counts_per_N = _gain3("gain_counts_per_N", gain_counts_per_N)
        self.electrode_baseline_counts = _scalar(
            "electrode_baseline_counts", electrode_baseline_counts
        )
        self.pdc_baseline_counts = _scalar("pdc_baseline_counts", pdc_baseline_counts)
        self.pdc_gain_counts_per_N = _scalar(
            "pdc_gain_counts_per_N", pdc_gain_counts_per_N, lo=0.0, strict=False
        )
        self.drive = linear_drive_matrix(self.gain_counts_per_N)

    def streams(self) -> dict[str, StreamSpec]:
        r = self.rate_hz
        return {
            "electrodes": _electrode_spec(r),
            "pdc": StreamSpec(
                "pdc",
                ("pdc",),
                {"pdc": "counts"},
                rate_hz=r,
                description="DC fluid pressure, ADC counts",
            ),
            "truth_force": StreamSpec(
                "truth_force",
                ("fx", "fy", "fz"),
                dict.fromkeys(("fx", "fy", "fz"), "N"),
                rate_hz=r,
                description="force plate: force the finger applies, finger frame (N)",
            ),
            "truth_contact": StreamSpec(
                "truth_contact",
                ("cx", "cy", "cz"),
                dict.fromkeys(("cx", "cy", "cz"), "mm"),
                rate_hz=r,
                description="contact point of the current press, finger frame",
            ),
        }

    def labels(self) -> dict[str, LabelSpec]:
        return {"slip_onset_s": LabelSpec("slip_onset_s", unit="s")}

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """Draw the trial's press train (enough presses to fill ``duration_s``)."""
        k = int(np.ceil(self.duration_s / (self.press_s[0] + self.rest_s[0]))) + 1
        return {
            "press_s": _draw(rng, self.press_s, k),
            "rest_s": _draw(rng, self.rest_s, k),
            "force_N": _draw(rng, self.force_N, k),
            "contact_s_mm": _draw(rng, self.contact_s_mm, k),
            "contact_phi_rad": np.deg2rad(_draw(rng, self.contact_phi_deg, k)),
            "dir_uv": rng.random((4, k)),
        }

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        del rng  # the backbone is deterministic given the drawn press train
        t = sample_times(self.duration_s, self.rate_hz)
        press, rest = params["press_s"], params["rest_s"]
        starts = np.concatenate([[0.0], np.cumsum(press + rest)[:-1]])
        points, normals = surface_point(
            params["contact_s_mm"], params["contact_phi_rad"]
        )
        half = np.deg2rad(self.cone_deg)
        uv = params["dir_uv"]
        d0 = cone_directions(normals, half, uv[0], uv[1])
        d1 = cone_directions(normals, half, uv[2], uv[3])
        idx = np.searchsorted(starts, t, side="right") - 1
        u = (t - starts[idx] - rest[idx]) / press[idx]
        inside = (u >= 0.0) & (u <= 1.0)
        uc = np.clip(u, 0.0, 1.0)[:, None]
        d = (1.0 - uc) * d0[idx] + uc * d1[idx]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        magnitude = np.where(
            inside, params["force_N"][idx] * np.sin(np.pi * uc[:, 0]) ** 2, 0.0
        )
        force = magnitude[:, None] * d
        baseline = np.full(len(ELECTRODE_NAMES), self.electrode_baseline_counts)
        normal_load = np.einsum("ij,ij->i", force, normals[idx])
        pdc = self.pdc_baseline_counts + self.pdc_gain_counts_per_N * normal_load
        return SceneState(
            time={"electrodes": t, "pdc": t, "truth_force": t, "truth_contact": t},
            signals={
                "electrodes": baseline + force @ self.drive.T,
                "pdc": pdc,
                "truth_force": force,
                "truth_contact": points[idx],
            },
            truth={
                "slip_onset_s": float("nan"),
                "electrode_baseline": baseline,
                "contact_start_s": starts,
                "contact_point_mm": points,
                "contact_normal": normals,
                "weighted_normals_scales": weighted_normals_scales(self.drive),
            },
        )

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        f = state.signals["truth_force"]
        c = state.signals["truth_contact"]
        streams = {
            "electrodes": _electrode_frame(
                state.time["electrodes"], state.signals["electrodes"]
            ),
            "pdc": _frame(state.time["pdc"], pdc=state.signals["pdc"]),
            "truth_force": _frame(
                state.time["truth_force"], fx=f[:, 0], fy=f[:, 1], fz=f[:, 2]
            ),
            "truth_contact": _frame(
                state.time["truth_contact"], cx=c[:, 0], cy=c[:, 1], cz=c[:, 2]
            ),
        }
        return streams, {"slip_onset_s": state.truth["slip_onset_s"]}, {}


class BioTacLiftSlip:
    """Grasp, hold and lift an object until it slips linearly or rotationally
    (Su et al. 2015, Sec. IV-B/C, V-B/C).

    Phases: ``press`` (grip force rises to ``Fn``), ``hold``, ``lift`` (the tangential
    load rises towards the finger's share of the weight ``W = load_share m g`` as
    ``W (1 - cos(pi t / load_s)) / 2``), ``slip`` and ``release`` (grip opens). The grip
    is set so static friction gives way at a fraction ``r`` of the weight, ``Fn = r W /
    mu_s``: the true onset ``t0`` is when the load reaches ``mu_s Fn``. From ``t0``
    the contact slips incipiently (tangential force held at ``mu_s Fn``); gross slip
    starts ``incipient_s`` later and the tangential force falls towards kinetic
    friction, ``Ft = mu_k Fn + (mu_s - mu_k) Fn exp(-(t - t0 - incipient_s) / tau)``,
    so ``dFt/dt < 0`` after the IMU sees the motion, as the paper's force-derivative
    detector does (4.7-18 ms after it). ``reference_onset_s = t0 + imu_delay_s``.
    Grasping at the centre of mass gives ``linear`` slip, at an edge ``rotational``
    (Sec. V-C); the class's electrode signature is the ``slip_deformation`` effect.

    The AC pressure backbone is the fluid's response to grip changes,
    ``pac = pac_baseline + pac_gain dFn/dt``; vibration is added by effects.

    Parameters
    ----------
    rate_hz, pac_rate_hz : float
        Electrode (300 Hz in the paper) and AC-pressure (2.2 kHz) sample rates.
    press_s, hold_s, load_s, slip_s, release_s : float or [low, high]
        Phase durations (s); ``load_s`` is the time the load ramp would take to reach
        the full weight (the lift phase ends at slip, earlier).
    objects : mapping
        Object name -> ``{mass_kg, mu_static, texture}``; one is drawn per trial.
    load_share : float
        Fraction of the object's weight carried by the BioTac's contact, (0, 1].
    slip_load_fraction : float or [low, high]
        ``r``: fraction of the weight at which static friction gives way, (0, 1).
    mu_kinetic_ratio : float
        ``mu_k / mu_s``, (0, 1].
    incipient_s, force_drop_tau_s : float
        Incipient-slip time before gross slip and tangential-force decay constant (s).
    imu_delay_s : float
        Lag of the object IMU's onset behind the true onset (s).
    slip_classes : list of str
        Classes drawn uniformly (``linear``, ``rotational``).
    contact_s_mm, contact_phi_deg : float or [low, high]
        Contact position on the core (see :class:`BioTacForceProbe`).
    load_direction_deg : float or [low, high]
        Direction of the load in the contact's tangent plane, from the finger's base
        (``-x``) towards ``+y`` (deg).
    gain_counts_per_N, electrode_baseline_counts : float
        As in :class:`BioTacForceProbe`.
    pac_baseline_counts, pac_gain_counts_per_N_s : float
        AC-pressure mid-scale reading (counts) and its response to dFn/dt (counts per
        N/s).
    """

    sensor = SENSOR
    groups: tuple[str, ...] = ("object",)

    def __init__(
        self,
        *,
        rate_hz: float = 300.0,
        pac_rate_hz: float = 2200.0,
        press_s: Any = 0.3,
        hold_s: Any = (0.3, 0.5),
        load_s: Any = 0.8,
        slip_s: Any = 0.3,
        release_s: Any = 0.2,
        objects: Mapping[str, Mapping[str, float]] | None = None,
        load_share: float = 0.5,
        slip_load_fraction: Any = (0.5, 0.85),
        mu_kinetic_ratio: float = 0.8,
        incipient_s: float = 0.055,
        force_drop_tau_s: float = 0.03,
        imu_delay_s: float = 0.045,
        slip_classes: Sequence[str] = SLIP_CLASSES,
        contact_s_mm: Any = (6.0, 12.0),
        contact_phi_deg: Any = (-10.0, 10.0),
        load_direction_deg: Any = (-20.0, 20.0),
        gain_counts_per_N: Any = 60.0,
        electrode_baseline_counts: float = 2000.0,
        pac_baseline_counts: float = 2048.0,
        pac_gain_counts_per_N_s: float = 2.0,
    ) -> None:
        self.rate_hz = _scalar("rate_hz", rate_hz, lo=0.0)
        self.pac_rate_hz = _scalar("pac_rate_hz", pac_rate_hz, lo=0.0)
        self.press_s = _range("press_s", press_s, lo=0.0, strict=True)
        self.hold_s = _range("hold_s", hold_s, lo=0.0)
        self.load_s = _range("load_s", load_s, lo=0.0, strict=True)
        self.slip_s = _range("slip_s", slip_s, lo=0.0, strict=True)
        self.release_s = _range("release_s", release_s, lo=0.0, strict=True)
        objs = DEFAULT_OBJECTS if objects is None else objects
        if not len(objs):
            raise SimulationError("objects must name at least one object")
        self.objects: dict[str, dict[str, float]] = {}
        for name, spec in objs.items():
            for key in ("mass_kg", "mu_static", "texture"):
                if key not in spec:
                    raise SimulationError(f"objects.{name} has no {key}")
            self.objects[str(name)] = {
                "mass_kg": _scalar(f"objects.{name}.mass_kg", spec["mass_kg"], lo=0.0),
                "mu_static": _scalar(
                    f"objects.{name}.mu_static", spec["mu_static"], lo=0.0
                ),
                "texture": _scalar(
                    f"objects.{name}.texture", spec["texture"], lo=0.0, strict=False
                ),
            }
        self.load_share = _scalar("load_share", load_share, lo=0.0)
        if self.load_share > 1.0:
            raise SimulationError(f"load_share must be <= 1; got {load_share}")
        self.slip_load_fraction = _range(
            "slip_load_fraction", slip_load_fraction, lo=0.0, hi=0.99, strict=True
        )
        self.mu_kinetic_ratio = _scalar("mu_kinetic_ratio", mu_kinetic_ratio, lo=0.0)
        if self.mu_kinetic_ratio > 1.0:
            raise SimulationError(
                f"mu_kinetic_ratio must be <= 1; got {mu_kinetic_ratio}"
            )
        self.incipient_s = _scalar("incipient_s", incipient_s, lo=0.0, strict=False)
        if self.incipient_s >= self.slip_s[0]:
            raise SimulationError(
                f"incipient_s must be shorter than slip_s; got {incipient_s} >= {slip_s}"
            )
        self.force_drop_tau_s = _scalar("force_drop_tau_s", force_drop_tau_s, lo=0.0)
        self.imu_delay_s = _scalar("imu_delay_s", imu_delay_s, lo=0.0, strict=False)
        classes = [str(c) for c in slip_classes]
        if not classes or set(classes) - set(SLIP_CLASSES):
            raise SimulationError(
                f"slip_classes must be a non-empty subset of {list(SLIP_CLASSES)}; "
                f"got {classes}"
            )
        self.slip_classes = tuple(classes)
        self.contact_s_mm = _range("contact_s_mm", contact_s_mm, lo=0.0, hi=MAX_S_MM)
        self.contact_phi_deg = _range(
            "contact_phi_deg", contact_phi_deg, lo=-180.0, hi=180.0
        )
        self.load_direction_deg = _range(
            "load_direction_deg", load_direction_deg, lo=-180.0, hi=180.0
        )
        self.gain_counts_per_N = _gain3("gain_counts_per_N", gain_counts_per_N)
        self.electrode_baseline_counts = _scalar(
            "electrode_baseline_counts", electrode_baseline_counts
        )
        self.pac_baseline_counts = _scalar("pac_baseline_counts", pac_baseline_counts)
        self.pac_gain_counts_per_N_s = _scalar(
            "pac_gain_counts_per_N_s", pac_gain_counts_per_N_s
        )
        self.drive = linear_drive_matrix(self.gain_counts_per_N)

    def streams(self) -> dict[str, StreamSpec]:
        names = ("fx", "fy", "fz", "ft", "fn")
        return {
            "electrodes": _electrode_spec(self.rate_hz),
            "pac": StreamSpec(
                "pac",
                ("pac",),
                {"pac": "counts"},
                rate_hz=self.pac_rate_hz,
                description="AC (hydro-acoustic) pressure, ADC counts",
            ),
            "truth_force": StreamSpec(
                "truth_force",
                names,
                dict.fromkeys(names, "N"),
                rate_hz=self.rate_hz,
                description="force the finger applies, finger frame; ft/fn tangential "
                "and normal to the contact",
            ),
        }

    def labels(self) -> dict[str, LabelSpec]:
        return {
            "slip_onset_s": LabelSpec("slip_onset_s", unit="s"),
            "reference_onset_s": LabelSpec(
                "reference_onset_s",
                unit="s",
                description="onset seen by the object IMU (true onset + imu_delay_s), s",
            ),
            "slip_class": LabelSpec("slip_class", classes=SLIP_CLASSES),
        }

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        names = list(self.objects)
        return {
            "object": names[int(rng.integers(len(names)))],
            "slip_class": self.slip_classes[int(rng.integers(len(self.slip_classes)))],
            "press_s": float(_draw(rng, self.press_s)),
            "hold_s": float(_draw(rng, self.hold_s)),
            "load_s": float(_draw(rng, self.load_s)),
            "slip_s": float(_draw(rng, self.slip_s)),
            "release_s": float(_draw(rng, self.release_s)),
            "slip_load_fraction": float(_draw(rng, self.slip_load_fraction)),
            "contact_s_mm": float(_draw(rng, self.contact_s_mm)),
            "contact_phi_rad": float(np.deg2rad(_draw(rng, self.contact_phi_deg))),
            "load_direction_rad": float(
                np.deg2rad(_draw(rng, self.load_direction_deg))
            ),
        }

    def _forces(
        self, t: np.ndarray, p: Mapping[str, Any]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Normal and tangential force (N) at times ``t``."""
        ph, fn_grip = p["phases"], p["grip_force_N"]
        weight, r = p["weight_N"], p["slip_load_fraction"]
        t_lift, t0 = ph["lift"][0], ph["slip"][0]
        t_rel, t_end = ph["release"]
        t_gross = t0 + self.incipient_s
        fn = fn_grip * smooth_step(t / ph["press"][1])
        fn = np.where(
            t >= t_rel, fn_grip * (1.0 - smooth_step((t - t_rel) / (t_end - t_rel))), fn
        )
        ft = np.minimum(weight * smooth_step((t - t_lift) / p["load_s"]), r * weight)
        mu_k_fn = self.mu_kinetic_ratio * r * weight  # mu_k Fn
        decay = mu_k_fn + (r * weight - mu_k_fn) * np.exp(
            -np.maximum(t - t_gross, 0.0) / self.force_drop_tau_s
        )
        ft = np.where(t >= t_gross, decay, ft)
        ft_rel = mu_k_fn + (r * weight - mu_k_fn) * np.exp(
            -max(t_rel - t_gross, 0.0) / self.force_drop_tau_s
        )
        ft = np.where(t >= t_rel, ft_rel * fn / fn_grip, ft)
        return fn, ft

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        del rng  # the backbone is deterministic given the drawn parameters
        obj = self.objects[params["object"]]
        r = params["slip_load_fraction"]
        weight = self.load_share * obj["mass_kg"] * GRAVITY_M_S2
        fn_grip = r * weight / obj["mu_static"]
        lift_s = params["load_s"] * float(np.arccos(1.0 - 2.0 * r)) / np.pi
        phases = phase_times(
            {
                "press": params["press_s"],
                "hold": params["hold_s"],
                "lift": lift_s,
                "slip": params["slip_s"],
                "release": params["release_s"],
            }
        )
        p = {**params, "phases": phases, "grip_force_N": fn_grip, "weight_N": weight}
        duration = phases["release"][1]
        t = sample_times(duration, self.rate_hz)
        t_pac = sample_times(duration, self.pac_rate_hz)
        point, normal = surface_point(params["contact_s_mm"], params["contact_phi_rad"])
        t1, t2 = tangent_frame(normal)
        psi = params["load_direction_rad"]
        load_dir = -np.cos(psi) * t1 + np.sin(psi) * t2
        fn, ft = self._forces(t, p)
        force = fn[:, None] * normal + ft[:, None] * load_dir
        baseline = np.full(len(ELECTRODE_NAMES), self.electrode_baseline_counts)
        fn_pac, _ = self._forces(t_pac, p)
        pac = self.pac_baseline_counts + self.pac_gain_counts_per_N_s * np.gradient(
            fn_pac, t_pac
        )
        onset = phases["slip"][0]
        return SceneState(
            time={"electrodes": t, "pac": t_pac, "truth_force": t},
            signals={
                "electrodes": baseline + force @ self.drive.T,
                "pac": pac,
                "truth_force": np.column_stack([force, ft, fn]),
            },
            truth={
                "slip_onset_s": onset,
                "reference_onset_s": onset + self.imu_delay_s,
                "gross_slip_s": onset + self.incipient_s,
                "slip_end_s": phases["release"][0],
                "slip_class": params["slip_class"],
                "object": params["object"],
                "texture": obj["texture"],
                "grip_force_N": fn_grip,
                "phases": phases,
                "electrode_baseline": baseline,
                "contact_start_s": np.zeros(1),
                "contact_point_mm": point.reshape(1, 3),
                "contact_normal": normal.reshape(1, 3),
                "load_direction": load_dir,
                "grip_t_s": t,
                "grip_fraction": fn / fn_grip,
            },
        )

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        f = state.signals["truth_force"]
        streams = {
            "electrodes": _electrode_frame(
                state.time["electrodes"], state.signals["electrodes"]
            ),
            "pac": _frame(state.time["pac"], pac=state.signals["pac"]),
            "truth_force": _frame(
                state.time["truth_force"],
                fx=f[:, 0],
                fy=f[:, 1],
                fz=f[:, 2],
                ft=f[:, 3],
                fn=f[:, 4],
            ),
        }
        labels = {
            "slip_onset_s": float(state.truth["slip_onset_s"]),
            "reference_onset_s": float(state.truth["reference_onset_s"]),
            "slip_class": str(state.truth["slip_class"]),
        }
        return streams, labels, {"object": str(state.truth["object"])}
