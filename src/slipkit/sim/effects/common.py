"""Sensor-agnostic effects: noise, ADC quantisation, drift, dropped frames, jitter.

Convention: ``signals[s]`` is aligned sample-for-sample with ``time[s]`` for every
stream ``s`` (first axis = samples); effects that drop or move samples keep both
in step.
"""

from __future__ import annotations

import numpy as np

from slipkit.sim.core import SceneState, SimulationError, register_effect


@register_effect("white_noise", draws={"sigma": "log"})
def white_noise(
    state: SceneState, rng: np.random.Generator, *, target: str, sigma: float
) -> SceneState:
    """Add zero-mean Gaussian noise of standard deviation ``sigma`` (signal units)."""
    x = state.signal(target, "white_noise")
    return state.with_signal(target, x + rng.normal(0.0, sigma, size=x.shape))


@register_effect("quantisation")
def quantisation(
    state: SceneState,
    rng: np.random.Generator,
    *,
    target: str,
    bits: int,
    full_scale: tuple[float, float],
) -> SceneState:
    """ADC quantisation: clip to ``full_scale`` (lo, hi) and round to ``2**bits`` levels."""
    del rng  # deterministic effect; the signature is shared by every effect
    lo, hi = map(float, full_scale)
    if not hi > lo or bits < 1:
        raise SimulationError(
            f"quantisation: need full_scale hi > lo and bits >= 1; got {full_scale}, {bits}"
        )
    lsb = (hi - lo) / (2**bits - 1)
    x = state.signal(target, "quantisation")
    return state.with_signal(
        target, lo + np.round((np.clip(x, lo, hi) - lo) / lsb) * lsb
    )


@register_effect("drift", draws={"rate_per_s": "uniform"})
def drift(
    state: SceneState, rng: np.random.Generator, *, target: str, rate_per_s: float
) -> SceneState:
    """Slow baseline drift: a random-sign linear ramp of ``rate_per_s`` units per second."""
    x = state.signal(target, "drift")
    t = state.time[target]
    slope = (
        rate_per_s * rng.choice([-1.0, 1.0], size=x.shape[1:])
        if x.ndim > 1
        else rate_per_s * rng.choice([-1.0, 1.0])
    )
    ramp = (t - t[0]).reshape((-1,) + (1,) * (x.ndim - 1)) * slope
    return state.with_signal(target, x + ramp)


@register_effect("dropped_frames", draws={"probability": "uniform"})
def dropped_frames(
    state: SceneState, rng: np.random.Generator, *, stream: str, probability: float
) -> SceneState:
    """Lose whole frames of ``stream`` at random with ``probability`` each (time gaps)."""
    x = state.signal(stream, "dropped_frames")
    keep = rng.random(len(x)) >= probability
    keep[0] = True  # a trial always starts with a frame
    return state.with_signal(stream, x[keep]).with_time(
        stream, state.time[stream][keep]
    )


@register_effect("timestamp_jitter", draws={"sigma_s": "log"})
def timestamp_jitter(
    state: SceneState, rng: np.random.Generator, *, stream: str, sigma_s: float
) -> SceneState:
    """Jitter the timestamps of ``stream`` by Gaussian noise (s); order is kept by sorting."""
    t = state.time[stream]
    return state.with_time(stream, np.sort(t + rng.normal(0.0, sigma_s, size=t.shape)))


@register_effect("channel_offset", draws={"sigma": "uniform"})
def channel_offset(
    state: SceneState, rng: np.random.Generator, *, target: str, sigma: float
) -> SceneState:
    """A per-trial baseline offset per channel: ``x_c + o_c``, ``o_c ~ N(0, sigma^2)``.

    Each channel keeps its offset for the whole trial (a re-seated sensor, another
    unit, a temperature shift since the last tare); ``sigma`` in signal units.
    Assumption: offsets are independent across channels and trials.
    """
    if not (np.isfinite(sigma) and sigma >= 0):
        raise SimulationError(
            f"effect 'channel_offset': sigma must be >= 0; got {sigma!r}"
        )
    x = state.signal(target, "channel_offset")
    offsets = rng.normal(0.0, sigma, size=x.shape[1:])
    return state.with_signal(target, x + offsets)
