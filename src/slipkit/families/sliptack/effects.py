"""SlipTack effects: nib stick-slip oscillation and gross (axial) nib deflection.

Both read the trial's object motion from ``state.truth["motion"]`` (set by the scene
models in :mod:`slipkit.families.sliptack.scene`) and add to the nib signal in mm.
Physics: :mod:`slipkit.families.sliptack.physics`; documentation: ``docs/families/sliptack.md``.
"""

from __future__ import annotations

import numpy as np

from slipkit.families.sliptack.physics import (
    ConstantSpeedMotion,
    cycle_bound,
    cycles_constant_speed,
    cycles_quasi_static,
    natural_frequency,
)
from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, register_effect


def _positive(value: float, key: str, effect: str) -> float:
    return params.number(f"effect {effect!r}: {key}", value, lo=0.0, strict_lo=True)


@register_effect("stick_slip")
def stick_slip(
    state: SceneState,
    rng: np.random.Generator,
    *,
    M_kg: float,
    k_l_N_m: float,
    target: str = "nib",
) -> SceneState:
    """Nib stick-slip oscillation, integrated exactly piecewise (SlipTack eqs. 1-2).

    Stick while ``mu_s Fn + A_n >= k_l u`` (the nib moves with the object); slip with
    ``M u'' = mu_k Fn - k_l u`` (eq. 1, solution eq. 2) until ``u'`` equals the object
    speed again. Breakaway and re-stick times are computed cycle by cycle
    (:func:`~slipkit.families.sliptack.physics.cycles_constant_speed` for a constant pull,
    :func:`~slipkit.families.sliptack.physics.cycles_quasi_static` for an accelerating object)
    and ``u(t)`` is evaluated at the stream's own timestamps, so a slow stream aliases
    the oscillation. Adds ``1000 u`` (mm) to ``signals[target]``.

    ``A_n`` is the adhesion term of cycle ``n`` (assumption, for acrylic, whose adhesion
    to the silicone skin the paper blames for its missing trend):
    ``A_n = 2 adhesion_N r^n / (1 + r^n) G_n`` with ``r = v / adhesion_ref_speed_mm_s``
    and ``n = adhesion_exponent``: rate-dependent tack that equals ``adhesion_N`` at the
    reference speed and saturates at twice that, times ``G_n``, gamma-distributed with
    mean 1 and coefficient of variation ``adhesion_cv`` (irregular cycles). Zero when
    the material has ``adhesion_N = 0`` (cherry, basswood follow the plain model).

    Parameters
    ----------
    M_kg : float
        Nib mass (kg); the paper's nib: 1.4e-5.
    k_l_N_m : float
        Nib lateral stiffness (N/m); the paper's nib: 9.45.
    target : str
        The nib stream's signal (mm).
    """
    name = "stick_slip"
    M = _positive(M_kg, "M_kg", name)
    k_l = _positive(k_l_N_m, "k_l_N_m", name)
    motion = state.truth_value("motion", name)
    x = state.signal(target, name)
    t = state.time[target]
    if not np.isfinite(motion.start_s) or len(t) == 0:
        return state.with_truth(stick_slip_cycles=None)
    mu_s = float(state.truth_value("mu_s", name))
    mu_k = float(state.truth_value("mu_k", name))
    adhesion = float(state.truth.get("adhesion_N", 0.0))
    end_s = float(t[-1])
    w0 = float(natural_frequency(M, k_l))
    n_max = cycle_bound(end_s - motion.start_s, w0)
    gains = None
    if adhesion > 0.0:
        cv = float(state.truth.get("adhesion_cv", 0.0))
        gains = rng.gamma(1.0 / cv**2, cv**2, size=n_max) if cv > 0 else np.ones(n_max)
    ref = float(state.truth.get("adhesion_ref_speed_mm_s", 50.0)) * 1e-3
    expo = float(state.truth.get("adhesion_exponent", 0.0))

    def tack(v: float) -> float:
        """Mean adhesion force (N) at object speed ``v`` (m/s)."""
        r = (max(v, 0.0) / ref) ** expo
        return 2.0 * adhesion * r / (1.0 + r)

    if isinstance(motion, ConstantSpeedMotion):
        excess = None if gains is None else tack(motion.v0_m_s) * gains
        cycles = cycles_constant_speed(motion, end_s, mu_s, mu_k, M, k_l, excess)
    elif gains is None:
        cycles = cycles_quasi_static(motion, end_s, mu_s, mu_k, M, k_l)
    else:
        draws = gains
        cycles = cycles_quasi_static(
            motion, end_s, mu_s, mu_k, M, k_l, lambda n, v: tack(v) * float(draws[n])
        )
    u_mm = 1e3 * cycles.evaluate(t)
    shaped = u_mm.reshape((-1,) + (1,) * (x.ndim - 1))
    return state.with_signal(target, x + shaped).with_truth(stick_slip_cycles=cycles)


@register_effect("gross_deflection", draws={"gain": "uniform"})
def gross_deflection(
    state: SceneState,
    rng: np.random.Generator,
    *,
    gain: float = 1.0,
    target: str = "nib",
) -> SceneState:
    """Gross nib deflection: the nib signal follows the axial deflection ``x - x0`` (mm).

    SlipTack eq. 4 estimates the drop acceleration ``a = g - mu_k k_a (x - x0) / m_t``
    from the sensed gross deflection (the feature G of Figs. 10-11, calibrated to the
    axial nib displacement). Adds ``gain (x(t) - x0)`` (signal units per mm) at the
    stream's timestamps; ``x(t)`` comes from the scene's motion (``axial_deflection``).
    """
    del rng  # deterministic
    name = "gross_deflection"
    motion = state.truth_value("motion", name)
    if not hasattr(motion, "axial_deflection"):
        raise SimulationError(
            f"effect {name!r} needs a motion with an axial deflection (a drop scene); "
            f"this scene's motion is {type(motion).__name__}"
        )
    x = state.signal(target, name)
    dx_mm = 1e3 * motion.axial_deflection(state.time[target])
    shaped = dx_mm.reshape((-1,) + (1,) * (x.ndim - 1))
    return state.with_signal(target, x + float(gain) * shaped)


@register_effect("nib_harmonics", draws={"ratio": "uniform", "phase_deg": "uniform"})
def nib_harmonics(
    state: SceneState,
    rng: np.random.Generator,
    *,
    ratio: float,
    phase_deg: float = 0.0,
    target: str = "nib",
) -> SceneState:
    """A second harmonic on the stick-slip oscillation, locked to its cycles.

    Between breakaways ``b_n`` and ``b_(n+1)`` (``truth["stick_slip_cycles"]``, so list
    it after ``stick_slip``) the cycle phase is ``phi = 2 pi (t - b_n) / (b_(n+1) - b_n)``;
    adds ``ratio a_n sin(2 phi + phase)`` (mm), with ``a_n = (2 / pi) D_n`` the
    fundamental amplitude of an ideal sawtooth of the cycle's peak-to-peak ``2 D_n``
    (``D_n = break_u - centre_u``). Evaluated at the stream's timestamps, so a slow
    stream aliases it like the fundamental. Observation (an independent signal
    generator): a second harmonic of 0.63 of the fundamental; the nib's read-out and a
    non-ideal release shape it, which the piecewise model leaves out. ``ratio`` is
    relative to ``a_n``; the measured ratio also carries the waveform's own harmonic
    (0.5 for an ideal sawtooth), at a phase set by ``phase_deg``.
    """
    del rng  # drawn by the core when given as a range
    name = "nib_harmonics"
    if not (np.isfinite(ratio) and ratio >= 0):
        raise SimulationError(f"effect {name!r}: ratio must be >= 0; got {ratio!r}")
    if not np.isfinite(phase_deg):
        raise SimulationError(
            f"effect {name!r}: phase_deg must be finite; got {phase_deg!r}"
        )
    cycles = state.truth.get("stick_slip_cycles")
    x = state.signal(target, name)
    if "stick_slip_cycles" not in state.truth:
        raise SimulationError(
            f"effect {name!r} needs the stick-slip cycles: list it after 'stick_slip'"
        )
    if cycles is None or cycles.n_cycles < 2:
        return state
    t = state.time[target]
    b = cycles.break_s
    n = np.searchsorted(b, t, side="right") - 1
    inside = (n >= 0) & (n < len(b) - 1)
    k = np.clip(n, 0, len(b) - 2)
    phi = 2.0 * np.pi * (t - b[k]) / (b[k + 1] - b[k])
    a = 1e3 * (2.0 / np.pi) * np.abs(cycles.break_u[k] - cycles.centre_u[k])
    extra = np.where(inside, ratio * a * np.sin(2.0 * phi + np.deg2rad(phase_deg)), 0.0)
    return state.with_signal(target, x + extra.reshape((-1,) + (1,) * (x.ndim - 1)))
