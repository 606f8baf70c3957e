"""FSR effects: the touch (press), stick-slip vibration events, gentle and sharp
impulsive disturbances, and the read-out's polarity.

Each acts on the physical normal force ``signals["force"]`` (N, aligned with the
``truth`` stream) and carries the change to the conditioned voltage ``signals["fsr"]``
through the inverse of the calibration eq. 6 (the difference ``V(F_new) - V(F_old)`` is
added, so voltage-domain effects listed earlier are kept). List them before the
voltage-domain effects (noise, quantisation). Source: Gentile et al. 2020; the scene is
:class:`slipkit.families.fsr.scene.FSRProbeSlide`; documentation: ``docs/families/fsr.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from slipkit.families.fsr.physics import (
    SLIP_COUNT_COEFF,
    SLIP_COUNT_FORCE_EXPONENT,
    SLIP_COUNT_PASS_EXPONENT,
    expected_slip_events,
    voltage_from_force,
)
from slipkit.sim.core import SceneState, SimulationError, register_effect


def _span(value: Any, key: str, effect: str, lo: float = 0.0) -> tuple[float, float]:
    """A number or ``[low, high]`` parameter, checked to be finite and >= ``lo``."""
    items = (
        list(value)
        if isinstance(value, Sequence) and not isinstance(value, str)
        else [value]
    )
    items = items * 2 if len(items) == 1 else items
    try:
        a, b = (float(v) for v in items)
    except (TypeError, ValueError):
        raise SimulationError(
            f"effect {effect!r}: {key} must be a number or [low, high]"
        ) from None
    if len(items) != 2 or not (np.isfinite(a) and np.isfinite(b)) or a < lo or b < a:
        raise SimulationError(
            f"effect {effect!r}: {key} must be a number or [low, high] with {lo} <= low <= high; "
            f"got {value!r}"
        )
    return a, b


def _uniform(
    rng: np.random.Generator, span: tuple[float, float], size: int
) -> np.ndarray:
    return (
        rng.uniform(span[0], span[1], size=size)
        if span[1] > span[0]
        else np.full(size, span[0])
    )


def _with_force(state: SceneState, force: np.ndarray, effect: str) -> SceneState:
    """Replace the force and carry the change to the voltage through eq. 6's inverse."""
    old = state.signal("force", effect)
    volts = state.signal("fsr", effect)
    coeffs = state.truth_value("calibration", effect)
    out_range = state.truth_value("output_range_V", effect)
    changed = np.flatnonzero(force != old)
    delta = np.zeros_like(old)
    if len(changed):
        delta[changed] = voltage_from_force(
            force[changed], coeffs, out_range
        ) - voltage_from_force(old[changed], coeffs, out_range)
    if state.truth.get("polarity") == "rising":
        delta = -delta  # fsr_polarity mirrored the voltage: changes mirror too
    t_fsr, t_truth = state.time["fsr"], state.time["truth_contact"]
    if t_fsr is not t_truth and not np.array_equal(t_fsr, t_truth):
        delta = np.interp(t_fsr, t_truth, delta)  # the fsr stream lost or moved frames
    return state.with_signal("force", force).with_signal("fsr", volts + delta)


@register_effect("fsr_touch", draws={"rise_s": "uniform"})
def fsr_touch(
    state: SceneState, rng: np.random.Generator, *, rise_s: float = 0.01
) -> SceneState:
    """The touch: the probe presses the FSR at ``truth["touch_s"]``.

    The force is zero before the touch and rises to the pressed force over ``rise_s``
    (raised cosine), so the voltage steps down from rest (the paper's stage 1, eqs. 2-3:
    ``v_rest - v_mean > delta``; Fig. 3, instant t0). Without this effect the probe is
    pressed from the first sample and there is no step.
    """
    del rng
    name = "fsr_touch"
    rise = float(rise_s)
    if not np.isfinite(rise) or rise < 0:
        raise SimulationError(f"effect {name!r}: rise_s must be >= 0; got {rise_s!r}")
    t = state.time["truth_contact"]
    t0 = float(state.truth_value("touch_s", name))
    frac = (
        np.clip((t - t0) / rise, 0.0, 1.0) if rise > 0 else (t >= t0).astype(np.float64)
    )
    profile = 0.5 * (1.0 - np.cos(np.pi * frac))
    return _with_force(state, state.signal("force", name) * profile, name)


@register_effect(
    "fsr_slip_events",
    draws={"decay_s": "uniform", "ring_hz": "uniform", "jitter": "uniform"},
)
def fsr_slip_events(
    state: SceneState,
    rng: np.random.Generator,
    *,
    coeff: float = SLIP_COUNT_COEFF,
    force_exponent: float = SLIP_COUNT_FORCE_EXPONENT,
    pass_exponent: float = SLIP_COUNT_PASS_EXPONENT,
    amplitude_frac: Any = (0.08, 0.16),
    decay_s: float = 0.003,
    ring_hz: float = 150.0,
    jitter: float = 0.3,
) -> SceneState:
    """Stick-slip vibration events while the probe slides over the sensor.

    Count per pass ``n ~ Poisson(c F^alpha T^beta)``, the law fitted to Table 3 of the
    paper (more events at higher normal force ``F``, fewer per pass for a shorter pass
    ``T``, a higher rate per second; :func:`slipkit.families.fsr.physics.expected_slip_events`).
    Event times: evenly spaced over the pass, each moved by up to ``jitter`` of the
    spacing (stick-slip is quasi-periodic). Each event releases the normal force abruptly
    and rings: ``dF(t) = -A exp(-t / decay_s) cos(2 pi ring_hz t)``, ``A`` a fraction
    ``amplitude_frac`` of the pressed force (assumption: the paper shows the events as
    sharp positive voltage-derivative spikes, Figs. 14-16, that exceed ``alpha = 8``).
    Marks ``slip_event = 1`` for ``3 decay_s`` after each onset (the ring-down to 5%;
    events closer than that merge in the indicator) and sets ``truth["n_slip_events"]``.
    """
    name = "fsr_slip_events"
    amp = _span(amplitude_frac, "amplitude_frac", name)
    decay = _span(decay_s, "decay_s", name)[0]
    ring = _span(ring_hz, "ring_hz", name)[0]
    jit = _span(jitter, "jitter", name)[0]
    if decay <= 0 or jit >= 0.5:
        raise SimulationError(
            f"effect {name!r}: need decay_s > 0 and 0 <= jitter < 0.5"
        )
    t = state.time["truth_contact"]
    force = state.signal("force", name)
    s0, s1 = map(float, state.truth_value("phases", name)["slide"])
    fn = float(state.truth_value("normal_force_N", name))
    mean = float(
        expected_slip_events(fn, s1 - s0, coeff, force_exponent, pass_exponent)
    )
    n = int(rng.poisson(mean))
    if n == 0 or len(t) < 2:
        return state.with_truth(n_slip_events=0)
    k = np.arange(n)
    onsets = s0 + (s1 - s0) * (k + 0.5 + jit * rng.uniform(-1.0, 1.0, size=n)) / n
    amps = fn * _uniform(rng, amp, n)
    rate = 1.0 / float(t[1] - t[0])
    idx = np.clip(np.searchsorted(t, onsets), 0, len(t) - 1)
    impulses = np.zeros(len(t))
    np.add.at(impulses, idx, amps)
    tau = np.arange(int(np.ceil(6.0 * decay * rate)) + 1) / rate
    kernel = -np.exp(-tau / decay) * np.cos(2.0 * np.pi * ring * tau)
    dforce = np.convolve(impulses, kernel)[: len(t)]
    width = max(1, round(3.0 * decay * rate))
    marks = np.zeros(len(t) + 1)
    np.add.at(marks, idx, 1.0)
    np.add.at(marks, np.minimum(idx + width, len(t)), -1.0)
    indicator = (np.cumsum(marks[:-1]) > 0).astype(np.float64)
    indicator = np.maximum(state.signal("slip_event", name), indicator)
    out = _with_force(state, force + dforce, name)
    return out.with_signal("slip_event", indicator).with_truth(n_slip_events=n)


@register_effect("fsr_disturbance")
def fsr_disturbance(
    state: SceneState,
    rng: np.random.Generator,
    *,
    count: Any = (1, 3),
    amplitude_frac: Any = (0.02, 0.06),
    duration_s: Any = (0.06, 0.15),
    margin_s: float = 0.05,
) -> SceneState:
    """Impulsive external disturbances that cause no slip, during the hold.

    The paper's 50 impulsive disturbances (Sec. 3.3, Fig. 19) changed the force without
    moving the object and stayed below the slip threshold. Each is a single smooth bump
    ``dF = s A (1 - cos(2 pi t / D)) / 2`` of random sign ``s`` (both signs), amplitude
    ``A`` a fraction ``amplitude_frac`` of the pressed force and duration ``D``
    (``duration_s``): its slope, at most ``pi A / D``, is far below a slip event's
    abrupt drop. ``count`` bumps (an integer range) are placed in the hold phase, at
    least ``margin_s`` from its ends; ``disturbance = 1`` marks them.
    """
    name = "fsr_disturbance"
    c_lo, c_hi = _span(count, "count", name)
    if c_lo != int(c_lo) or c_hi != int(c_hi):
        raise SimulationError(
            f"effect {name!r}: count must be whole numbers; got {count!r}"
        )
    amp = _span(amplitude_frac, "amplitude_frac", name)
    dur = _span(duration_s, "duration_s", name)
    margin = _span(margin_s, "margin_s", name)[0]
    if dur[0] <= 0:
        raise SimulationError(f"effect {name!r}: duration_s must be > 0")
    h0, h1 = map(float, state.truth_value("phases", name)["hold"])
    lo, hi = h0 + margin, h1 - margin
    n = int(rng.integers(int(c_lo), int(c_hi) + 1))
    if n == 0:
        return state
    if hi - lo < dur[1]:
        raise SimulationError(
            f"effect {name!r}: the hold phase ({h1 - h0:.3g} s) cannot fit a {dur[1]} s bump "
            f"with margin_s={margin}; lengthen model.hold_s or shorten duration_s"
        )
    t = state.time["truth_contact"]
    fn = float(state.truth_value("normal_force_N", name))
    durations = _uniform(rng, dur, n)
    starts = lo + rng.uniform(0.0, 1.0, size=n) * (hi - lo - durations)
    signs = rng.choice(np.array([-1.0, 1.0]), size=n)
    amps = signs * fn * _uniform(rng, amp, n)
    force = state.signal("force", name).copy()
    marks = state.signal("disturbance", name).copy()
    for start, length, a in zip(starts, durations, amps, strict=True):  # a few bumps
        i0, i1 = np.searchsorted(t, [start, start + length])
        phase = (t[i0:i1] - start) / length
        force[i0:i1] += a * 0.5 * (1.0 - np.cos(2.0 * np.pi * phase))
        marks[i0:i1] = 1.0
    return _with_force(state, force, name).with_signal("disturbance", marks)


POLARITIES = ("falling", "rising")


@register_effect(
    "fsr_polarity", draws={"polarity": "choice"}, replay_groups=("polarity",)
)
def fsr_polarity(
    state: SceneState, rng: np.random.Generator, *, polarity: str = "falling"
) -> SceneState:
    """The conditioning circuit's polarity: ``falling`` (the paper's: the voltage falls
    as the force rises) or ``rising`` (the common voltage divider, ``V = Vcc R_m /
    (R_m + R_FSR)``, whose output rises with force).

    ``rising`` mirrors the voltage inside the output range, ``V <- lo + hi - V``
    (``truth["output_range_V"]``): the same calibration read backwards, so rest sits
    at ``lo + hi - V_rest`` (0.5 V for the default 4.5 V rest in 0-5 V) and every
    force change moves the voltage the other way. Force-domain effects listed after
    this one follow the mirrored polarity (``truth["polarity"]``); voltage-domain
    effects (noise, quantisation) are symmetric and may come before or after. Give
    ``[falling, rising]`` to draw one per trial. Assumption: the mirror keeps the
    calibration's shape; a real divider's curve differs in detail.
    """
    del rng  # drawn by the core when given as a list
    name = "fsr_polarity"
    if polarity not in POLARITIES:
        raise SimulationError(
            f"effect {name!r}: polarity must be one of {list(POLARITIES)}; got {polarity!r}"
        )
    if state.truth.get("polarity", "falling") == polarity:
        return state.with_truth(polarity=polarity)
    lo, hi = map(float, state.truth_value("output_range_V", name))
    volts = state.signal("fsr", name)
    return state.with_signal("fsr", (lo + hi) - volts).with_truth(polarity=polarity)


@register_effect("fsr_impulse_disturbance")
def fsr_impulse_disturbance(
    state: SceneState,
    rng: np.random.Generator,
    *,
    count: Any = (1, 3),
    amplitude_frac: Any = (0.15, 0.5),
    rise_s: Any = (0.001, 0.005),
    duration_s: Any = (0.005, 0.05),
    margin_s: float = 0.05,
) -> SceneState:
    """Sharp impulsive disturbances during the hold: knocks with a millisecond rise.

    Each is a trapezoid with raised-cosine edges: the force changes by ``s A`` over
    ``r`` (``rise_s``), stays there and returns over ``r`` at the end of its duration
    ``D`` (``duration_s``; ``r`` is capped at ``D / 2``). ``s`` is a random sign,
    ``A`` a fraction ``amplitude_frac`` of the pressed force (< 0.95, so the force stays
    positive), and ``count`` (whole numbers ``[lo, hi]``) knocks fall in the hold phase,
    at least ``margin_s`` from its ends; every range is drawn per knock. Its slope,
    up to ``pi A / (2 r)``, reaches a slip event's; ``disturbance = 1`` marks it.
    Observation (an independent signal generator): +-15-50 % of the holding
    force, millisecond rise, 5-50 ms long, where ``fsr_disturbance`` gives the paper's
    gentle 2-6 %, 60-150 ms bumps. The shape is an assumption.
    """
    name = "fsr_impulse_disturbance"
    c_lo, c_hi = _span(count, "count", name)
    if c_lo != int(c_lo) or c_hi != int(c_hi):
        raise SimulationError(
            f"effect {name!r}: count must be whole numbers; got {count!r}"
        )
    amp = _span(amplitude_frac, "amplitude_frac", name)
    if amp[1] >= 0.95:
        raise SimulationError(
            f"effect {name!r}: amplitude_frac must stay below 0.95; got {amplitude_frac!r}"
        )
    rise = _span(rise_s, "rise_s", name)
    dur = _span(duration_s, "duration_s", name)
    margin = _span(margin_s, "margin_s", name)[0]
    if dur[0] <= 0 or rise[0] <= 0:
        raise SimulationError(f"effect {name!r}: duration_s and rise_s must be > 0")
    h0, h1 = map(float, state.truth_value("phases", name)["hold"])
    lo, hi = h0 + margin, h1 - margin
    n = int(rng.integers(int(c_lo), int(c_hi) + 1))
    if n == 0:
        return state
    if hi - lo < dur[1]:
        raise SimulationError(
            f"effect {name!r}: the hold phase ({h1 - h0:.3g} s) cannot fit a {dur[1]} s knock "
            f"with margin_s={margin}; lengthen model.hold_s or shorten duration_s"
        )
    t = state.time["truth_contact"]
    fn = float(state.truth_value("normal_force_N", name))
    durations = _uniform(rng, dur, n)
    rises = np.minimum(_uniform(rng, rise, n), durations / 2.0)
    starts = lo + rng.uniform(0.0, 1.0, size=n) * (hi - lo - durations)
    signs = rng.choice(np.array([-1.0, 1.0]), size=n)
    amps = signs * fn * _uniform(rng, amp, n)
    force = state.signal("force", name).copy()
    marks = state.signal("disturbance", name).copy()
    for start, length, r, a in zip(starts, durations, rises, amps, strict=True):
        i0, i1 = np.searchsorted(t, [start, start + length])
        tau = t[i0:i1] - start
        edge = np.clip(np.minimum(tau, length - tau) / r, 0.0, 1.0)
        force[i0:i1] += a * 0.5 * (1.0 - np.cos(np.pi * edge))
        marks[i0:i1] = 1.0
    return _with_force(state, force, name).with_signal("disturbance", marks)
