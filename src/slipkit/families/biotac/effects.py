"""BioTac effects: electrode non-linearity, slip deformation, AC-pressure vibration.

Electrode effects act on the impedance change ``E = x - baseline`` of a stream of
absolute counts (``truth["electrode_baseline"]``, one value per electrode), so that
ADC quantisation and clipping can follow them. Each one is a departure from the
backbone's linear response ``E = A F`` (:func:`slipkit.families.biotac.physics.linear_drive_matrix`),
which obeys the weighted-normals relation of Su et al. 2015 (Sec. IV-A) exactly; the
paper attributes that method's situation-dependent offsets to "the highly non-linear
deformation on the silicon skin" (Sec. V-A), and these effects are that non-linearity.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import signal as sps

from slipkit.families.biotac.physics import (
    ELECTRODE_POSITIONS_MM,
    N_ELECTRODES,
    neighbour_kernel,
    proximity_weights,
)
from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, register_effect


def _electrode_delta(
    state: SceneState, target: str, effect: str
) -> tuple[np.ndarray, np.ndarray]:
    """(counts, baseline) of an electrode stream; checks it has 19 channels."""
    x = state.signal(target, effect)
    if x.ndim != 2 or x.shape[1] != N_ELECTRODES:
        raise SimulationError(
            f"effect {effect!r}: signal {target!r} has shape {x.shape}; "
            f"expected (n, {N_ELECTRODES}) electrode counts"
        )
    base = np.asarray(state.truth_value("electrode_baseline", effect), dtype=np.float64)
    return x, base


def _positive(effect: str, **values: float) -> None:
    for key, value in values.items():
        params.number(f"effect {effect!r}: {key}", value, lo=0.0, strict_lo=True)


def _press_values(
    state: SceneState, t: np.ndarray, effect: str, key: str
) -> tuple[np.ndarray, np.ndarray]:
    """``truth[key]`` (one 3-vector per press) and the index of the press in force at
    each time ``t``: presses start at ``truth["contact_start_s"]``, the last one
    started applies."""
    starts = np.asarray(state.truth_value("contact_start_s", effect), dtype=np.float64)
    values = np.asarray(state.truth_value(key, effect), dtype=np.float64).reshape(-1, 3)
    if len(values) != len(starts):
        raise SimulationError(
            f"effect {effect!r}: truth {key!r} has {len(values)} rows for "
            f"{len(starts)} contact starts"
        )
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
    return values, idx


@register_effect("contact_locality")
def contact_locality(
    state: SceneState,
    rng: np.random.Generator,
    *,
    target: str = "electrodes",
    width_mm: float,
    depth: float,
) -> SceneState:
    """Electrodes near the contact respond more than distant ones.

    ``E_i <- E_i ((1 - depth) + depth exp(-|p_i - c(t)|^2 / (2 width^2)))`` with
    ``p_i`` the electrode centre and ``c(t)`` the contact point (``truth``
    ``contact_start_s`` / ``contact_point_mm``). Observation: the BioTac's impedance
    "tends to be dominated by the thickness of the liquid between the electrode and the
    immediately overlying skin" (Su et al. 2015, Sec. III), so the same force at another
    place gives another pattern; the Gaussian form is an assumption. ``depth = 0``
    leaves the response location-independent.
    """
    del rng  # deterministic
    _positive("contact_locality", width_mm=width_mm)
    if not 0.0 <= float(depth) <= 1.0:
        raise SimulationError(
            f"effect 'contact_locality': depth must be in [0, 1]; got {depth}"
        )
    x, base = _electrode_delta(state, target, "contact_locality")
    points, idx = _press_values(
        state, state.time[target], "contact_locality", "contact_point_mm"
    )
    gain = ((1.0 - depth) + depth * proximity_weights(points, width_mm))[idx]
    return state.with_signal(target, base + (x - base) * gain)


@register_effect("electrode_coupling", draws={"strength": "uniform"})
def electrode_coupling(
    state: SceneState,
    rng: np.random.Generator,
    *,
    target: str = "electrodes",
    strength: float,
    length_mm: float,
) -> SceneState:
    """Fluid squeezed from over a compressed electrode thickens the layer over its
    neighbours.

    ``E_i <- E_i - strength sum_j K_ij max(E_j, 0)``, ``K_ij = exp(-d_ij^2 / (2 l^2))``
    (``K_ii = 0``, ``d_ij`` the distance between electrode centres). Only compressed
    electrodes (``E_j > 0``) push fluid away, which makes the cross-talk non-linear.
    Source: the skin "is inflated with an incompressible and conductive liquid ...
    the liquid is displaced, resulting in distributed impedance changes" (Su et al.
    2015, Sec. III); the kernel form is an assumption.
    """
    del rng  # deterministic
    _positive("electrode_coupling", length_mm=length_mm)
    if float(strength) < 0.0:
        raise SimulationError(
            f"effect 'electrode_coupling': strength must be >= 0; got {strength}"
        )
    x, base = _electrode_delta(state, target, "electrode_coupling")
    e = x - base
    k = neighbour_kernel(length_mm, ELECTRODE_POSITIONS_MM)
    return state.with_signal(target, x - strength * (np.maximum(e, 0.0) @ k.T))


@register_effect("electrode_saturation")
def electrode_saturation(
    state: SceneState,
    rng: np.random.Generator,
    *,
    target: str = "electrodes",
    saturation_counts: float | Sequence[float],
) -> SceneState:
    """Saturating impedance response: ``E_i <- s_i tanh(E_i / s_i)``.

    The fluid layer over an electrode can only thin until the skin meets the core (and
    only thicken as far as the skin stretches), so the impedance change levels off at
    ``+-s_i`` counts while staying linear (slope 1) for small loads. ``s_i`` is one
    value or one per electrode. Source: Su et al. 2015, Sec. V-A (non-linear skin
    deformation); the tanh form is an assumption.
    """
    del rng  # deterministic
    s = np.broadcast_to(
        np.asarray(saturation_counts, dtype=np.float64), (N_ELECTRODES,)
    )
    if not np.all(s > 0.0):
        raise SimulationError(
            "effect 'electrode_saturation': saturation_counts must be > 0; "
            f"got {saturation_counts}"
        )
    x, base = _electrode_delta(state, target, "electrode_saturation")
    return state.with_signal(target, base + s * np.tanh((x - base) / s))


@register_effect("slip_deformation")
def slip_deformation(
    state: SceneState,
    rng: np.random.Generator,
    *,
    target: str = "electrodes",
    gain_counts_per_mm: float,
    drag_mm: float,
    twist_deg: float,
    tau_s: float,
    width_mm: float,
) -> SceneState:
    """Skin dragged by the slipping object shifts the electrode pattern.

    The skin near the contact ``c`` is displaced by ``a(t) u(p)`` with
    ``u = drag d`` for linear slip (the object slides along the load direction ``d``)
    and ``u = twist n × (p - c)`` for rotational slip (the object turns about the
    contact normal ``n``). Electrode ``i`` changes by
    ``gain w_i a(t) (u(p_i) . d)``, ``w_i = exp(-|p_i - c|^2 / (2 width^2))``: under
    linear slip electrodes on either side of the load line move together (same sign),
    under rotational slip they move against each other (opposite signs). ``a(t) = (1 -
    exp(-(t - t0) / tau)) g(t)`` from the true onset ``t0``, with ``g`` the grip
    fraction (``truth`` ``grip_t_s`` / ``grip_fraction``) so the skin relaxes on release.
    Source: the two slip classes of Su et al. 2015, Sec. IV-C; the projection onto
    ``d`` and the exponential build-up are assumptions.
    """
    del rng  # deterministic
    _positive("slip_deformation", tau_s=tau_s, width_mm=width_mm)
    x, _ = _electrode_delta(state, target, "slip_deformation")
    onset = float(state.truth_value("slip_onset_s", "slip_deformation"))
    if not np.isfinite(onset):
        return state
    cls = str(state.truth_value("slip_class", "slip_deformation"))
    at = np.array([onset])
    points, i = _press_values(state, at, "slip_deformation", "contact_point_mm")
    normals, _ = _press_values(state, at, "slip_deformation", "contact_normal")
    c, n = points[i[0]], normals[i[0]]
    d = np.asarray(state.truth_value("load_direction", "slip_deformation"), dtype=float)
    r = ELECTRODE_POSITIONS_MM - c
    if cls == "linear":
        along = np.full(N_ELECTRODES, float(drag_mm))
    elif cls == "rotational":
        along = np.deg2rad(float(twist_deg)) * (np.cross(n, r) @ d)
    else:
        raise SimulationError(
            f"effect 'slip_deformation': slip_class {cls!r} is not linear/rotational"
        )
    t = state.time[target]
    grip = np.interp(
        t,
        np.asarray(state.truth_value("grip_t_s", "slip_deformation"), float),
        np.asarray(state.truth_value("grip_fraction", "slip_deformation"), float),
    )
    a = np.where(t >= onset, -np.expm1(-np.maximum(t - onset, 0.0) / tau_s), 0.0)
    pattern = gain_counts_per_mm * proximity_weights(c, width_mm) * along
    return state.with_signal(target, x + (a * grip)[:, None] * pattern[None, :])


def _band_noise(
    rng: np.random.Generator,
    n: int,
    rate_hz: float,
    band_hz: tuple[float, float],
    order: int,
    effect: str,
) -> np.ndarray:
    """Unit-RMS Gaussian noise band-limited to ``band_hz`` by a Butterworth SOS."""
    lo, hi = (float(v) for v in band_hz)
    nyq = 0.5 * rate_hz
    if not 0.0 < lo < hi < nyq:
        raise SimulationError(
            f"effect {effect!r}: band must satisfy 0 < lo < hi < {nyq} Hz (Nyquist); "
            f"got {band_hz}"
        )
    if int(order) < 1:
        raise SimulationError(f"effect {effect!r}: order must be >= 1; got {order}")
    sos = sps.butter(int(order), [lo, hi], btype="bandpass", fs=rate_hz, output="sos")
    pre = int(np.ceil(10.0 * rate_hz / lo))  # let the filter's start-up transient pass
    y = sps.sosfilt(sos, rng.standard_normal(n + pre))[pre:]
    rms = float(np.sqrt(np.mean(y**2))) if n else 1.0
    return y / rms if rms > 0 else y


def _along(v: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``v`` (one value per sample) shaped to broadcast over ``x``'s channels."""
    return v.reshape((-1,) + (1,) * (x.ndim - 1))


def _rate(t: np.ndarray, effect: str, target: str) -> float:
    if len(t) < 2:
        raise SimulationError(f"effect {effect!r}: stream {target!r} has < 2 samples")
    return float((len(t) - 1) / (t[-1] - t[0]))


@register_effect(
    "motor_vibration", draws={"freq_hz": "uniform", "rms_counts": "uniform"}
)
def motor_vibration(
    state: SceneState,
    rng: np.random.Generator,
    *,
    target: str = "pac",
    freq_hz: float,
    linewidth_hz: float,
    rms_counts: float,
) -> SceneState:
    """Tonal vibration of the robot's motors on the AC pressure, at all times.

    ``x += sqrt(2) rms sin(2 pi f t + phi(t))`` with a random-walk phase ``phi``
    (Wiener phase noise, increments of variance ``2 pi linewidth dt``), which spreads
    the tone into a narrow line of full width ``linewidth_hz`` at constant amplitude.
    Source: Su et al. 2015, Sec. IV-B: the slip threshold is "twice as large as the
    baseline vibration caused by the motors of the robot"; the tonal form, frequency
    and level are assumptions.
    """
    _positive("motor_vibration", freq_hz=freq_hz)
    if float(linewidth_hz) < 0 or float(rms_counts) < 0:
        raise SimulationError(
            "effect 'motor_vibration': linewidth_hz and rms_counts must be >= 0; "
            f"got {linewidth_hz}, {rms_counts}"
        )
    x = state.signal(target, "motor_vibration")
    t = state.time[target]
    dt = np.diff(t, prepend=t[0])
    steps = rng.standard_normal(len(t)) * np.sqrt(2.0 * np.pi * linewidth_hz * dt)
    phase = 2.0 * np.pi * (freq_hz * t + rng.random()) + np.cumsum(steps)
    tone = np.sqrt(2.0) * rms_counts * np.sin(phase)
    return state.with_signal(target, x + _along(tone, x))


@register_effect("slip_vibration", draws={"rms_counts": "uniform"})
def slip_vibration(
    state: SceneState,
    rng: np.random.Generator,
    *,
    target: str = "pac",
    band_hz: tuple[float, float] = (60.0, 700.0),
    rms_counts: float,
    ramp_s: float = 0.005,
    order: int = 4,
) -> SceneState:
    """Slip micro-vibration of the fingerprint ridges on the AC pressure, during slip.

    Gaussian noise band-passed to ``band_hz`` (Butterworth, SOS), scaled to
    ``rms_counts`` times the object's ``texture`` (``truth``), gated to the slip
    interval ``[slip_onset_s, slip_end_s)`` with raised-cosine edges of ``ramp_s``.
    Source: Su et al. 2015, Sec. IV-B: "slip-related micro-vibration" on the textured
    skin, detected by band-passing the 2.2 kHz pressure at 60-700 Hz; the level is an
    assumption.
    """
    if float(rms_counts) < 0 or float(ramp_s) < 0:
        raise SimulationError(
            "effect 'slip_vibration': rms_counts and ramp_s must be >= 0; "
            f"got {rms_counts}, {ramp_s}"
        )
    x = state.signal(target, "slip_vibration")
    onset = float(state.truth_value("slip_onset_s", "slip_vibration"))
    if not np.isfinite(onset):
        return state
    end = float(state.truth_value("slip_end_s", "slip_vibration"))
    texture = float(state.truth.get("texture", 1.0))
    t = state.time[target]
    ramp = max(float(ramp_s), 1e-9)
    rise = np.clip((t - onset) / ramp, 0.0, 1.0)
    fall = np.clip((end - t) / ramp, 0.0, 1.0)
    gate = 0.25 * (1.0 - np.cos(np.pi * rise)) * (1.0 - np.cos(np.pi * fall))
    noise = _band_noise(
        rng,
        len(x),
        _rate(t, "slip_vibration", target),
        (band_hz[0], band_hz[1]),
        order,
        "slip_vibration",
    )
    return state.with_signal(target, x + _along(rms_counts * texture * gate * noise, x))
