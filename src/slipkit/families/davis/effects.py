"""DAVIS effects: events from contact-area change, vibration incidents and background
noise (Rigi et al. 2018, Sensors 18(2):333).

The ``events`` signal is an integer array (n, 3) of ``x, y, polarity`` aligned with
``time["events"]`` (s); every effect appends its events and keeps the stream sorted
by time. Polarity follows the paper (Sec. 3.1): a pixel that the contact darkens
fires negative events, a pixel that loses contact (brightens) fires positive ones.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from slipkit.families.davis.physics import ContactPatch
from slipkit.sim.core import SceneState, SimulationError, register_effect


def _patch(state: SceneState, effect: str) -> ContactPatch:
    patch = state.truth.get("patch")
    if not isinstance(patch, ContactPatch):
        raise SimulationError(
            f"effect {effect!r} needs a DAVIS scene (truth['patch']); this scene has none"
        )
    return patch


def _append(
    state: SceneState,
    effect: str,
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    pol: np.ndarray,
) -> SceneState:
    """Add events and keep the stream sorted by time (stable: ties keep their order)."""
    old = np.asarray(state.signal("events", effect)).reshape(-1, 3)
    new = np.column_stack([x, y, pol]).astype(np.int64)
    times = np.concatenate([np.asarray(state.time["events"], dtype=np.float64), t])
    rows = np.concatenate([old, new])
    order = np.argsort(times, kind="stable")
    return state.with_signal("events", rows[order]).with_time("events", times[order])


def _pair(
    key: str, value: float | Sequence[float], *, effect: str, allow_zero: bool
) -> tuple[float, float]:
    lo, hi = (
        (float(value), float(value))
        if isinstance(value, int | float)
        else (float(value[0]), float(value[1]))
    )
    if not (lo <= hi and (lo >= 0 if allow_zero else lo > 0)):
        raise SimulationError(
            f"effect {effect!r}: {key} must be a number or [lo, hi] with {'0 <=' if allow_zero else '0 <'} lo <= hi; got {value!r}"
        )
    return lo, hi


@register_effect("contact_events")
def contact_events(
    state: SceneState,
    rng: np.random.Generator,
    *,
    events_per_pixel: int = 1,
    spacing_s: float = 1e-4,
    latency_s: float = 1.2e-5,
) -> SceneState:
    """Events where the patch edge crosses a pixel: -1 when it becomes covered, +1 when uncovered.

    Paper, Sec. 3.1: "The increase of input force results in expanding the contact
    area as well as darkening this region ... negative-polarity events. In contrast,
    during the releasing phase, a loss of contact area results in brightening these
    regions; therefore, it leads to trigger positive-polarity events." A DVS pixel
    fires one event per contrast-threshold step of its log intensity (Sec. 2.2), so a
    crossing gives ``events_per_pixel`` events ``spacing_s`` apart; each event lags by
    an exponential pixel latency of mean ``latency_s`` (assumption; the paper quotes
    12 µs temporal resolution). Crossing times are exact per pixel (backbone).
    """
    if (
        int(events_per_pixel) != events_per_pixel
        or events_per_pixel < 1
        or spacing_s < 0
        or latency_s < 0
    ):
        raise SimulationError(
            "effect 'contact_events': need an integer events_per_pixel >= 1, spacing_s >= 0, latency_s >= 0; "
            f"got {events_per_pixel!r}, {spacing_s!r}, {latency_s!r}"
        )
    _patch(state, "contact_events")
    px = np.asarray(state.signal("pixels", "contact_events"))
    crossings = np.concatenate([state.signals["t_cover"], state.signals["t_uncover"]])
    pol = np.repeat([-1, 1], len(px))
    xy = np.concatenate([px, px])
    keep = np.isfinite(crossings)
    crossings, pol, xy = crossings[keep], pol[keep], xy[keep]
    n = int(events_per_pixel)
    t = (crossings[:, None] + spacing_s * np.arange(n)[None, :]).ravel()
    if latency_s > 0:
        t = t + rng.exponential(latency_s, size=t.shape)
    return _append(
        state,
        "contact_events",
        t,
        np.repeat(xy[:, 0], n),
        np.repeat(xy[:, 1], n),
        np.repeat(pol, n),
    )


@register_effect("vibration_incidents", draws={"rate_hz": "uniform"})
def vibration_incidents(
    state: SceneState,
    rng: np.random.Generator,
    *,
    rate_hz: float = 4.0,
    shift_px: float | Sequence[float] = (1.0, 3.0),
    dilation: float | Sequence[float] = (0.0, 0.05),
    rise_s: float = 0.003,
    fall_s: float = 0.015,
) -> SceneState:
    """Object vibration: short bursts of both polarities with no net loss of contact.

    Paper, Sec. 3.2: "In vibration, both positive-polarity and negative-polarity
    events are observed"; Fig. 6b: the object loses contact on one side while gaining
    it on the other, and the contact area increases; Fig. 14 / Sec. 5: vibration
    incidents occur in the grasping phase. Model (assumption): incidents arrive as a
    Poisson process of ``rate_hz`` during press and hold. In an incident the patch
    (frozen at its current size ``r``) shifts by ``s(τ)`` px along a random direction
    and dilates by ``1 + D s / A``; ``s`` rises linearly to ``A`` in ``rise_s`` and
    returns to 0 in ``fall_s``. A pixel at normalised position ``d`` is covered when
    ``|d - s e|^2 <= r^2 (1 + D s / A)^2`` (``e`` the shift per px in normalised
    units), a quadratic in ``s`` solved per pixel: each root in (0, A) gives one
    event on the rise and the opposite one on the fall, so every incident has as many
    positive as negative events and the area returns to its value.
    """
    a_lo, a_hi = _pair(
        "shift_px", shift_px, effect="vibration_incidents", allow_zero=False
    )
    d_lo, d_hi = _pair(
        "dilation", dilation, effect="vibration_incidents", allow_zero=True
    )
    if rate_hz < 0 or not rise_s > 0 or not fall_s > 0:
        raise SimulationError(
            f"effect 'vibration_incidents': need rate_hz >= 0, rise_s > 0, fall_s > 0; got {rate_hz!r}, {rise_s!r}, {fall_s!r}"
        )
    patch = _patch(state, "vibration_incidents")
    width, height = state.truth["sensor_shape"]
    start, stop = patch.press_start, patch.release_start - rise_s - fall_s
    span = max(stop - start, 0.0)
    starts = np.sort(rng.uniform(start, start + span, size=rng.poisson(rate_hz * span)))
    ts: list[np.ndarray] = []
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    ps: list[np.ndarray] = []
    for t0 in starts:  # a few incidents per trial; each is vectorised over pixels
        amp = rng.uniform(a_lo, a_hi)
        dil = rng.uniform(d_lo, d_hi)
        theta = rng.uniform(0.0, 2.0 * np.pi)
        r = float(patch.radius(t0))
        if r * min(patch.a, patch.b) < 1.0:
            continue
        x, y = patch.bbox(r * (1.0 + dil), amp + 2.0, width, height)
        du, dv = patch.normalised(x.astype(np.float64), y.astype(np.float64))
        eu, ev = patch.normalised(
            np.array(patch.cx + np.cos(theta)), np.array(patch.cy + np.sin(theta))
        )
        g = dil / amp
        alpha = eu**2 + ev**2 - (r * g) ** 2
        beta = du * eu + dv * ev + r**2 * g
        gamma = du**2 + dv**2 - r**2
        disc = beta**2 - alpha * gamma
        root = np.sqrt(np.clip(disc, 0.0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            roots = np.stack([(beta - root) / alpha, (beta + root) / alpha])
        valid = (disc > 0) & (roots > 0) & (roots < amp)
        slope = (
            alpha * roots - beta
        )  # sign of df/ds: > 0 means the pixel becomes uncovered
        j, i = np.nonzero(valid)
        s = roots[j, i]
        rise_pol = np.where(slope[j, i] > 0, 1, -1)
        ts += [t0 + rise_s * s / amp, t0 + rise_s + fall_s * (1.0 - s / amp)]
        xs += [x[i], x[i]]
        ys += [y[i], y[i]]
        ps += [rise_pol, -rise_pol]
    if not ts:
        return state.with_truth(vibration_starts_s=starts)
    out = _append(
        state,
        "vibration_incidents",
        np.concatenate(ts),
        np.concatenate(xs),
        np.concatenate(ys),
        np.concatenate(ps),
    )
    return out.with_truth(vibration_starts_s=starts)


@register_effect("background_events", draws={"rate_hz": "log"})
def background_events(
    state: SceneState, rng: np.random.Generator, *, rate_hz: float = 2000.0
) -> SceneState:
    """Background noise: events scattered uniformly over the array, time and polarity.

    Paper, Sec. 3.1: "a number of events have been triggered outside the contact
    area, which are considered as noise events ... widely scattered around the
    frame". Model (assumption): a homogeneous Poisson process of ``rate_hz`` events
    per second over the whole array, polarity +1 or -1 with equal probability.
    """
    if rate_hz < 0:
        raise SimulationError(
            f"effect 'background_events': rate_hz must be >= 0; got {rate_hz!r}"
        )
    _patch(state, "background_events")
    width, height = state.truth["sensor_shape"]
    duration = float(state.truth["duration_s"])
    n = int(rng.poisson(rate_hz * duration))
    t = rng.uniform(0.0, duration, size=n)
    x = rng.integers(0, width, size=n)
    y = rng.integers(0, height, size=n)
    pol = rng.choice(np.array([-1, 1]), size=n)
    return _append(state, "background_events", t, x, y, pol)
