"""SlipTack nib stick-slip: closed-form relations and the piecewise-exact trajectory.

Model (SlipTack paper, Section III-A): a nib of mass ``M`` on a lateral spring ``k_l``
is dragged by an object moving at speed ``v0`` under a per-nib normal load ``Fn``.

* stick: the nib moves with the object (``u' = v0``) while ``mu_s Fn >= k_l u``;
* slip: ``M u'' = mu_k Fn - k_l u`` (eq. 1), i.e. ``u = A sin(w0 (t - tau)) + mu_k Fn / k_l``
  (eq. 2) with ``w0 = sqrt(k_l / M)``, until the relative velocity ``u' - v0`` is zero
  again, when the nib re-sticks.

Two forms of the stick-slip frequency ``f = 1 / (tau_stick + tau_slip)`` (eq. 3) live here:

``exact``
    Solving the oscillator from breakaway (``u = mu_s Fn / k_l``, ``u' = v0``) to re-stick
    gives ``tau_stick = 2 (mu_s - mu_k) Fn / (k_l v0)`` and
    ``tau_slip = (pi + 2 atan(v0 / (w0 d))) / w0`` with ``d = (mu_s - mu_k) Fn / k_l``.
    This is the steady-state period of the integrated oscillator.
``paper``
    The paper's ``tau_stick = mu_s Fn / (k_l v0)`` (the nib restarts from ``u = 0``
    each cycle) and the half period of the nib ``tau_slip = pi / w0`` (the paper prints
    ``pi w0 / 2``, which is not a time). ``f = 1 / (mu_s Fn / (k_l v0) + pi / w0)``.

Units are SI throughout: m, m/s, m/s^2, N, kg, N/m, s, Hz. Every function broadcasts
over numpy arrays. numpy only: no pandas, torch, scikit-learn or Hydra here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

Form = Literal["exact", "paper"]
FloatArray = NDArray[np.float64]

#: Gravitational acceleration used by eq. 4 by default (m/s^2).
G_M_S2 = 9.81


def _f(x: ArrayLike) -> FloatArray:
    return np.asarray(x, dtype=np.float64)


# -- closed-form relations ------------------------------------------------------------
def natural_frequency(M_kg: ArrayLike, k_l_N_m: ArrayLike) -> FloatArray:
    """Nib natural angular frequency ``w0 = sqrt(k_l / M)`` (rad/s).

    The paper's nib (``M = 1.4e-5 kg``, ``k_l = 9.45 N/m``) gives 821.6 rad/s (130.8 Hz).
    """
    return np.sqrt(_f(k_l_N_m) / _f(M_kg))


def slip_half_amplitude(
    normal_force_N: ArrayLike, mu_s: ArrayLike, mu_k: ArrayLike, k_l_N_m: ArrayLike
) -> FloatArray:
    """``d = (mu_s - mu_k) Fn / k_l`` (m): breakaway deflection above the slip centre.

    The steady oscillation swings between ``mu_k Fn / k_l - d`` and ``mu_s Fn / k_l``.
    """
    return (_f(mu_s) - _f(mu_k)) * _f(normal_force_N) / _f(k_l_N_m)


def tau_stick_exact(
    v0_m_s: ArrayLike,
    normal_force_N: ArrayLike,
    mu_s: ArrayLike,
    mu_k: ArrayLike,
    k_l_N_m: ArrayLike,
) -> FloatArray:
    """Exact steady stick time ``2 (mu_s - mu_k) Fn / (k_l v0)`` (s); ``inf`` at ``v0 = 0``."""
    v0 = _f(v0_m_s)
    with np.errstate(divide="ignore"):
        return 2.0 * slip_half_amplitude(normal_force_N, mu_s, mu_k, k_l_N_m) / v0


def tau_slip_exact(
    v0_m_s: ArrayLike,
    normal_force_N: ArrayLike,
    mu_s: ArrayLike,
    mu_k: ArrayLike,
    M_kg: ArrayLike,
    k_l_N_m: ArrayLike,
) -> FloatArray:
    """Exact slip time ``(pi + 2 atan(v0 / (w0 d))) / w0`` (s).

    Between ``pi / w0`` (``v0 -> 0``) and ``2 pi / w0`` (``v0 -> inf``).
    """
    w0 = natural_frequency(M_kg, k_l_N_m)
    d = slip_half_amplitude(normal_force_N, mu_s, mu_k, k_l_N_m)
    return (np.pi + 2.0 * np.arctan2(_f(v0_m_s), w0 * d)) / w0


def tau_stick_paper(
    v0_m_s: ArrayLike, normal_force_N: ArrayLike, mu_s: ArrayLike, k_l_N_m: ArrayLike
) -> FloatArray:
    """The paper's stick time ``mu_s Fn / (k_l v0)`` (s): the nib restarts from ``u = 0``."""
    with np.errstate(divide="ignore"):
        return _f(mu_s) * _f(normal_force_N) / (_f(k_l_N_m) * _f(v0_m_s))


def tau_slip_paper(M_kg: ArrayLike, k_l_N_m: ArrayLike) -> FloatArray:
    """The paper's slip time, corrected to a half nib period ``pi / w0`` (s)."""
    return np.pi / natural_frequency(M_kg, k_l_N_m)


def stick_slip_frequency(
    v0_m_s: ArrayLike,
    normal_force_N: ArrayLike,
    mu_s: ArrayLike,
    mu_k: ArrayLike,
    M_kg: ArrayLike,
    k_l_N_m: ArrayLike,
    form: Form = "exact",
) -> FloatArray:
    """Stick-slip frequency ``f = 1 / (tau_stick + tau_slip)`` (Hz), eq. 3.

    Parameters
    ----------
    v0_m_s : array_like
        Pull speed (m/s); ``f = 0`` at ``v0 = 0``.
    normal_force_N : array_like
        Normal load on one nib (N).
    mu_s, mu_k : array_like
        Static and kinetic friction coefficients (``mu_k < mu_s``).
    M_kg, k_l_N_m : array_like
        Nib mass (kg) and lateral stiffness (N/m).
    form : {"exact", "paper"}
        ``exact``: the integrated oscillator's period (module docstring); ``paper``:
        ``1 / (mu_s Fn / (k_l v0) + pi / w0)``, which overestimates the exact frequency
        (by 0.04% at 10 mm/s to about 2% at 100 mm/s for the paper's nib).
    """
    if form == "exact":
        stick = tau_stick_exact(v0_m_s, normal_force_N, mu_s, mu_k, k_l_N_m)
        slip = tau_slip_exact(v0_m_s, normal_force_N, mu_s, mu_k, M_kg, k_l_N_m)
    elif form == "paper":
        stick = tau_stick_paper(v0_m_s, normal_force_N, mu_s, k_l_N_m)
        slip = tau_slip_paper(M_kg, k_l_N_m)
    else:
        raise ValueError(f"form must be 'exact' or 'paper'; got {form!r}")
    return 1.0 / (stick + slip)


def saturation_frequency(
    M_kg: ArrayLike, k_l_N_m: ArrayLike, form: Form = "exact"
) -> FloatArray:
    """The frequency ``f`` approaches as ``v0 -> inf`` (Hz).

    ``exact``: ``w0 / (2 pi)`` (the slip lasts a whole nib period, the stick vanishes);
    ``paper``: ``w0 / pi``. Inverting ``f(v0)`` for speed is undefined at and above it.
    """
    w0 = natural_frequency(M_kg, k_l_N_m)
    if form == "exact":
        return w0 / (2.0 * np.pi)
    if form == "paper":
        return w0 / np.pi
    raise ValueError(f"form must be 'exact' or 'paper'; got {form!r}")


def drop_acceleration(
    deflection_m: ArrayLike,
    mu_k: ArrayLike,
    k_a_N_m: ArrayLike,
    m_t_kg: ArrayLike,
    g_m_s2: float = G_M_S2,
) -> FloatArray:
    """Downward acceleration of a sliding object, eq. 4: ``a = g - mu_k k_a (x - x0) / m_t``.

    ``deflection_m`` is the gross axial nib deflection ``x - x0`` (m), ``k_a`` the axial
    stiffness of the sensor surface (N/m), ``m_t`` the total object mass (kg).
    """
    return g_m_s2 - _f(mu_k) * _f(k_a_N_m) * _f(deflection_m) / _f(m_t_kg)


# -- object motion driving the nib ----------------------------------------------------------
class ObjectMotion(Protocol):
    """Kinematics of the object the nibs touch, as the stick-slip integrator needs them.

    ``start_s`` is when relative motion starts (NaN: never).
    """

    start_s: float

    def state_at(self, t: float) -> tuple[float, float, float]:
        """Object speed (m/s), acceleration (m/s^2) and per-nib normal load (N) at ``t`` (s)."""
        ...


@dataclass(frozen=True)
class ConstantSpeedMotion:
    """An object pulled at constant speed ``v0_m_s`` from ``start_s`` on, at rest before.

    ``normal_force_N`` is the (constant) normal load on one nib.
    """

    v0_m_s: float
    start_s: float
    normal_force_N: float

    def position(self, t: ArrayLike) -> FloatArray:
        """Object displacement (m) since the pull started (0 before)."""
        return self.v0_m_s * np.maximum(_f(t) - self.start_s, 0.0)

    def speed(self, t: ArrayLike) -> FloatArray:
        """``v0`` from ``start_s`` on, 0 before (m/s)."""
        return np.where(_f(t) >= self.start_s, self.v0_m_s, 0.0)

    def acceleration(self, t: ArrayLike) -> FloatArray:
        """Zero (m/s^2): the pull speed is reached while the string is slack."""
        return np.zeros_like(_f(t))

    def nib_normal_force(self, t: ArrayLike) -> FloatArray:
        """The constant per-nib normal load (N)."""
        return np.full_like(_f(t), self.normal_force_N)

    def state_at(self, t: float) -> tuple[float, float, float]:
        """Speed (m/s), acceleration (m/s^2) and per-nib normal load (N) at ``t`` (s)."""
        return (self.v0_m_s if t >= self.start_s else 0.0), 0.0, self.normal_force_N


# -- the piecewise-exact trajectory ------------------------------------------------------------
@dataclass(frozen=True)
class StickSlipCycles:
    """Event table of a nib trajectory, one row per stick-slip cycle ``n``.

    Cycle ``n`` sticks on ``[restick_s[n], break_s[n])``, where
    ``u = stick_u[n] + stick_v[n] tau + stick_a[n] tau^2 / 2`` (``tau`` from the re-stick),
    then slips on ``[break_s[n], restick_s[n + 1])``, where
    ``u = centre_u[n] + D cos(w0 s) + (slip_v[n] / w0) sin(w0 s)``
    (``s`` from the breakaway, ``D = break_u[n] - centre_u[n]``): eq. 2 started at
    ``u = break_u[n]``, ``u' = slip_v[n]``. ``restick_s[0]`` is when the motion starts
    (the nib at ``stick_u[0]``); ``restick_s`` has one more entry than the other arrays.

    Attributes
    ----------
    restick_s, break_s : ndarray
        Re-stick and breakaway times (s).
    stick_u, break_u, centre_u : ndarray
        Nib deflection at re-stick, at breakaway and the slip centre ``mu_k Fn / k_l`` (m).
    stick_v, stick_a, slip_v : ndarray
        Object speed at re-stick (m/s), its acceleration during the stick (m/s^2) and
        its speed during the slip (m/s).
    w0 : float
        Nib natural angular frequency (rad/s).
    """

    restick_s: FloatArray
    break_s: FloatArray
    stick_u: FloatArray
    stick_v: FloatArray
    stick_a: FloatArray
    break_u: FloatArray
    centre_u: FloatArray
    slip_v: FloatArray
    w0: float

    @property
    def n_cycles(self) -> int:
        """Number of cycles in the table."""
        return len(self.break_s)

    @property
    def periods_s(self) -> FloatArray:
        """Breakaway-to-breakaway intervals (s)."""
        return np.diff(self.break_s)

    def evaluate(self, t: ArrayLike, before: float = 0.0) -> FloatArray:
        """Nib deflection ``u`` (m) at times ``t`` (s), vectorised over samples.

        ``before`` is returned before the motion starts; after the last cycle the nib
        is held at its last re-stick deflection.
        """
        t = _f(t)
        n = self.n_cycles
        out = np.full(t.shape, before, dtype=np.float64)
        if n == 0:
            return out
        k = np.searchsorted(self.restick_s, t, side="right") - 1
        started = k >= 0
        beyond = k >= n
        kk = np.clip(k, 0, n - 1)
        in_stick = started & ~beyond & (t < self.break_s[kk])
        in_slip = started & ~beyond & ~in_stick
        tau = t - self.restick_s[kk]
        stick = self.stick_u[kk] + tau * (
            self.stick_v[kk] + 0.5 * self.stick_a[kk] * tau
        )
        s = self.w0 * (t - self.break_s[kk])
        d = self.break_u[kk] - self.centre_u[kk]
        slip = (
            self.centre_u[kk] + d * np.cos(s) + (self.slip_v[kk] / self.w0) * np.sin(s)
        )
        out = np.where(in_stick, stick, out)
        out = np.where(in_slip, slip, out)
        if beyond.any():
            last = self.centre_u[-1] - (self.break_u[-1] - self.centre_u[-1])
            out = np.where(beyond, last, out)
        return out


def _slip_time(v: FloatArray | float, d: FloatArray | float, w0: float) -> FloatArray:
    """Time from breakaway to re-stick for a slip starting ``d`` above its centre (s)."""
    return _f((np.pi + 2.0 * np.arctan2(v, w0 * np.asarray(d))) / w0)


def cycle_bound(duration_s: float, w0: float) -> int:
    """An upper bound on the cycles in ``duration_s``: every slip lasts at least ``pi / w0``."""
    return int(np.ceil(max(duration_s, 0.0) * w0 / np.pi)) + 2


def cycles_constant_speed(
    motion: ConstantSpeedMotion,
    end_s: float,
    mu_s: float,
    mu_k: float,
    M_kg: float,
    k_l_N_m: float,
    excess_N: ArrayLike | None = None,
    u0_m: float = 0.0,
) -> StickSlipCycles:
    """Exact stick-slip cycles for a constant pull speed, from ``motion.start_s`` to ``end_s``.

    The nib starts at rest at ``u0_m`` and sticks until ``k_l u`` reaches the breakaway
    force ``mu_s Fn + excess_N[n]``; each slip is eq. 2 started at the breakaway with
    ``u' = v0`` and ends when ``u' = v0`` again, which happens at ``w0 s = pi + 2 phi``
    (``tan phi = v0 / (w0 D)``) with the nib mirrored to ``centre - D``. The event times
    follow cycle by cycle from these durations (a cumulative sum, no per-sample loop).

    Parameters
    ----------
    excess_N : array_like, optional
        Extra breakaway force of each cycle (N, >= 0): an adhesion term. Needs at least
        :func:`cycle_bound` ``(end_s - start_s, w0)`` entries; omitted: the plain model.
    """
    w0 = float(natural_frequency(M_kg, k_l_N_m))
    v0, fn = float(motion.v0_m_s), float(motion.normal_force_N)
    n_max = cycle_bound(end_s - motion.start_s, w0)
    centre = mu_k * fn / k_l_N_m
    thresholds = np.full(n_max, mu_s * fn / k_l_N_m)
    if excess_N is not None:
        extra = _f(excess_N)
        if len(extra) < n_max:
            raise ValueError(f"excess_N needs >= {n_max} entries; got {len(extra)}")
        thresholds = thresholds + extra[:n_max] / k_l_N_m
    d = thresholds - centre
    stick_u = np.empty(n_max)
    stick_u[0] = u0_m
    stick_u[1:] = centre - d[:-1]
    stick = (thresholds - stick_u) / v0
    slip = _slip_time(v0, d, w0)
    restick = np.empty(n_max + 1)
    restick[0] = motion.start_s
    restick[1:] = motion.start_s + np.cumsum(stick + slip)
    n = int(np.searchsorted(restick, end_s, side="right"))  # cycles starting by end_s
    n = max(1, min(n, n_max))
    return StickSlipCycles(
        restick_s=restick[: n + 1],
        break_s=restick[:n] + stick[:n],
        stick_u=stick_u[:n],
        stick_v=np.full(n, v0),
        stick_a=np.zeros(n),
        break_u=thresholds[:n],
        centre_u=np.full(n, centre),
        slip_v=np.full(n, v0),
        w0=w0,
    )


def cycles_quasi_static(
    motion: ObjectMotion,
    end_s: float,
    mu_s: float,
    mu_k: float,
    M_kg: float,
    k_l_N_m: float,
    excess_N: Callable[[int, float], float] | None = None,
    u0_m: float = 0.0,
) -> StickSlipCycles:
    """Stick-slip cycles under an accelerating object, one cycle at a time.

    Each stick uses the object's speed and acceleration at the re-stick (constant over
    the stick: ``u = u_r + v tau + a tau^2 / 2``, solved exactly for the breakaway);
    each slip freezes the object speed at its breakaway value (a slip lasts less than
    ``2 pi / w0``, short against the acceleration's time scale) and is solved exactly
    as in :func:`cycles_constant_speed`. The per-nib normal load is read at each
    re-stick. With zero acceleration and constant load this is the exact solution.

    Parameters
    ----------
    excess_N : callable (cycle index, speed at re-stick in m/s) -> N, optional
        Extra breakaway force of a cycle (an adhesion term).
    """
    w0 = float(natural_frequency(M_kg, k_l_N_m))
    n_max = cycle_bound(end_s - motion.start_s, w0)
    cols: dict[str, list[float]] = {
        k: [] for k in ("restick", "brk", "u", "v", "a", "bu", "cu", "sv")
    }
    t_r, u_r = float(motion.start_s), float(u0_m)
    for n in range(n_max):
        if t_r > end_s:
            break
        v, a, fn = motion.state_at(t_r)
        centre = mu_k * fn / k_l_N_m
        s_n = mu_s * fn / k_l_N_m
        if excess_N is not None:
            s_n += excess_N(n, v) / k_l_N_m
        gap = max(s_n - u_r, 0.0)
        if a > 0.0:
            tau = 2.0 * gap / (v + math.sqrt(v * v + 2.0 * a * gap))
        elif v > 0.0:
            tau = gap / v
        else:  # the object never moves: the nib stays stuck
            break
        v_b = v + a * tau
        d = s_n - centre
        cols["restick"].append(t_r)
        cols["brk"].append(t_r + tau)
        cols["u"].append(u_r)
        cols["v"].append(v)
        cols["a"].append(a)
        cols["bu"].append(s_n)
        cols["cu"].append(centre)
        cols["sv"].append(v_b)
        t_r = t_r + tau + (math.pi + 2.0 * math.atan2(v_b, w0 * d)) / w0
        u_r = centre - d
    brk = np.asarray(cols["brk"])
    return StickSlipCycles(
        restick_s=np.asarray([*cols["restick"], t_r])
        if len(brk)
        else np.asarray([t_r]),
        break_s=brk,
        stick_u=np.asarray(cols["u"]),
        stick_v=np.asarray(cols["v"]),
        stick_a=np.asarray(cols["a"]),
        break_u=np.asarray(cols["bu"]),
        centre_u=np.asarray(cols["cu"]),
        slip_v=np.asarray(cols["sv"]),
        w0=w0,
    )
