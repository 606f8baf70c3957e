"""GelSight effects: shake disturbances, gel shear and spreading, the marker grid's image,
blur and lighting drift (the scene: :mod:`slipkit.families.gelsight.scene`).

Order in a scene: ``shake`` (adds to the drag and twist the held object puts on the gel),
``gel_shear`` (moves the markers), ``marker_grid`` (draws the frames), then the image
effects ``blur`` and ``lighting_drift`` (and camera noise, the shared ``white_noise`` on
``frames_<camera>``). The image effects act on every fingertip's frames.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter

from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, register_effect


def _frames(state: SceneState, effect: str) -> list[str]:
    keys = sorted(k for k in state.signals if k.startswith("frames_"))
    if not keys:
        raise SimulationError(
            f"effect {effect!r} acts on camera frames: list it after 'marker_grid'"
        )
    return keys


def _num(effect: str, key: str, value: Any, **bounds: Any) -> float:
    return params.number(f"effect {effect!r}: {key}", value, **bounds)


def _cameras(state: SceneState, effect: str) -> dict[str, dict[str, Any]]:
    cams: dict[str, dict[str, Any]] = state.truth_value("cameras", effect)
    return cams


@register_effect(
    "shake",
    draws={"count": "choice"},
)
def shake(
    state: SceneState,
    rng: np.random.Generator,
    *,
    count: Any = 2,
    amplitude: Any = (0.03, 0.2),
    freq_hz: Any = (0.5, 3.0),
    duration_s: Any = (0.5, 2.5),
    twist_rad: Any = 0.0,
) -> SceneState:
    """Shake disturbances: ``count`` bursts of an oscillating tangential drag (and twist)
    on the held object, which shear the gel and return, without slip.

    Each burst has a Hann envelope over ``duration_s`` at a uniform time in the trial, a
    sinusoid of ``freq_hz`` with a random phase along a random direction, and a peak of
    ``amplitude`` pitches of marker displacement at the contact centre (``twist_rad``:
    peak rotation of the patch, rad). Ranges are drawn per burst. The gel only carries
    the drag while it holds the object (``gel_shear`` scales it by the load), so a
    shake after the object has left moves nothing. List it before ``gel_shear``.
    """
    name = "shake"
    if state.truth.get("gel_sheared"):
        raise SimulationError(f"effect {name!r} must be listed before 'gel_shear'")
    n = int(_num(name, "count", count, lo=0))
    spans = {
        k: params.value_range(f"effect {name!r}: {k}", v, lo=0.0)
        for k, v in (
            ("amplitude", amplitude),
            ("freq_hz", freq_hz),
            ("duration_s", duration_s),
            ("twist_rad", twist_rad),
        )
    }
    if spans["duration_s"][0] <= 0:
        raise SimulationError(f"effect {name!r}: duration_s must be > 0")
    t = next(iter(state.time.values()))
    drag = np.array(state.signal("drag", name), dtype=np.float64)
    twist = np.array(state.signal("twist", name), dtype=np.float64)
    end = float(t[-1]) if len(t) else 0.0
    bursts = []
    for _ in range(n):
        amp = params.draw(rng, spans["amplitude"], skip_fixed=False)
        f = params.draw(rng, spans["freq_hz"], skip_fixed=False)
        dur = params.draw(rng, spans["duration_s"], skip_fixed=False)
        tw = params.draw(rng, spans["twist_rad"], skip_fixed=False)
        start = rng.uniform(0.0, max(end - dur, 0.0))
        phase = rng.uniform(0.0, 2 * np.pi)
        ang = rng.uniform(0.0, 2 * np.pi)
        s = np.clip((t - start) / dur, 0.0, 1.0)
        env = np.sin(np.pi * s) ** 2
        wave = env * np.sin(2 * np.pi * f * (t - start) + phase)
        drag += amp * wave[:, None] * np.array([np.cos(ang), np.sin(ang)])[None, :]
        twist += tw * wave
        bursts.append((float(start), float(dur)))
    return (
        state.with_signal("drag", drag)
        .with_signal("twist", twist)
        .with_truth(shake_bursts=bursts)
    )


@register_effect("gel_shear", draws={"follow": "uniform"})
def gel_shear(
    state: SceneState, rng: np.random.Generator, *, follow: float = 0.7
) -> SceneState:
    """The markers' motion: gel spreading under the normal load, shear from the drag and
    twist, and the contact patch moving with a sliding object.

    For a marker at rest position ``p`` (pitches), with the contact centre
    ``c(t) = c0 + follow * slide(t)`` and ``q = p - c(t)``, the displacement is
    ``load(t) * w(q) * (spread * q + drag(t) + twist(t) * J q)`` pitches, where
    ``w(q) = exp(-|q|^2 / (2 R^2))`` is the contact patch (``R``: the object's contact
    radius) and ``J q`` is ``q`` turned by 90 degrees. A sliding object drags the
    spreading pattern with it (``follow``: the share of the slide the patch follows);
    as the load falls to zero the gel returns to rest. ``camera_2`` sees the world's x
    mirrored.
    """
    del rng
    name = "gel_shear"
    follow = _num(name, "follow", follow, lo=0.0, hi=1.0)
    load = np.asarray(state.signal("load", name))
    slide = np.asarray(state.signal("slide", name))
    drag = np.asarray(state.signal("drag", name))
    twist = np.asarray(state.signal("twist", name))
    radius = float(state.truth_value("contact_radius", name))
    spread = float(state.truth_value("spread", name))
    out = state
    for cam, geo in _cameras(state, name).items():
        key = f"markers_{cam}"
        marks = np.asarray(state.signal(key, name))
        pitch = float(geo["pitch_px"])
        flip = np.array([-1.0, 1.0]) if geo["mirror"] else np.ones(2)
        sign = -1.0 if geo["mirror"] else 1.0
        rest = (marks[0] - np.asarray(geo["contact_px"])) / pitch  # (m, 2) pitches
        centre = follow * slide * flip  # (n, 2)
        q = rest[None, :, :] - centre[:, None, :]
        w = np.exp(-np.sum(q * q, axis=-1) / (2 * radius**2))  # (n, m)
        jq = np.stack([-q[..., 1], q[..., 0]], axis=-1)
        disp = (
            spread * q + (drag * flip)[:, None, :] + (sign * twist)[:, None, None] * jq
        )
        disp *= (load[:, None] * w)[..., None]
        out = out.with_signal(key, marks + pitch * disp)
    return out.with_truth(gel_sheared=True)


@register_effect(
    "marker_grid",
    draws={"radius_px": "uniform", "contrast": "uniform", "background": "uniform"},
)
def marker_grid(
    state: SceneState,
    rng: np.random.Generator,
    *,
    radius_px: float = 3.5,
    contrast: float = 70.0,
    background: float = 110.0,
    vignette: float = 0.2,
) -> SceneState:
    """Grey camera frames of the marker grid: a dark dot per marker on the lit gel.

    Each marker is a Gaussian dot (s.d. ``radius_px / 1.5``) ``contrast`` grey levels
    deep on a ``background`` that falls off by ``vignette`` (a share) towards the
    corners. Adds ``frames_<camera>`` (n, height, width; grey levels, float) for every
    fingertip; the scene tracks them when it renders the trial.
    """
    del rng
    name = "marker_grid"
    r = _num(name, "radius_px", radius_px, lo=0.5)
    c = _num(name, "contrast", contrast, lo=0.0, hi=255.0)
    bg = _num(name, "background", background, lo=0.0, hi=255.0)
    vig = _num(name, "vignette", vignette, lo=0.0, hi=1.0)
    h, w = state.truth_value("frame_size", name)
    sd = r / 1.5
    y = np.arange(h, dtype=np.float32)
    x = np.arange(w, dtype=np.float32)
    ry = (y - h / 2) / (h / 2)
    rx = (x - w / 2) / (w / 2)
    light = bg * (1.0 - vig * 0.5 * (ry[:, None] ** 2 + rx[None, :] ** 2))
    out = state
    for cam in _cameras(state, name):
        marks = np.asarray(state.signal(f"markers_{cam}", name), dtype=np.float64)
        dots = _dots(marks, h, w, sd)
        frames = light[None] - c * np.minimum(dots, 1.0)
        out = out.with_signal(f"frames_{cam}", frames.astype(np.float32))
    return out


def _dots(marks: np.ndarray, h: int, w: int, sd: float, chunk: int = 50) -> np.ndarray:
    """Sum of unit Gaussian dots (s.d. ``sd`` px) at ``marks`` (n, m, 2) on (n, h, w).

    Each dot is drawn on its own patch of +-3 s.d. and the patches summed with
    ``numpy.bincount`` (a dense sum over every marker and pixel costs ~50 times more).
    """
    n = marks.shape[0]
    half = int(np.ceil(3 * sd))
    off = np.arange(-half, half + 1)
    out = np.empty((n, h, w), dtype=np.float32)
    for a in range(0, n, chunk):
        mk = marks[a : a + chunk]
        k = len(mk)
        xs = np.floor(mk[..., 0])[..., None].astype(np.int64) + off  # (k, m, p)
        ys = np.floor(mk[..., 1])[..., None].astype(np.int64) + off
        gx = np.exp(-0.5 * ((xs - mk[..., 0:1]) / sd) ** 2) * ((xs >= 0) & (xs < w))
        gy = np.exp(-0.5 * ((ys - mk[..., 1:2]) / sd) ** 2) * ((ys >= 0) & (ys < h))
        weight = gy[..., :, None] * gx[..., None, :]  # (k, m, p, p)
        frame = np.arange(k)[:, None, None, None] * (h * w)
        idx = (
            frame
            + np.clip(ys, 0, h - 1)[..., :, None] * w
            + np.clip(xs, 0, w - 1)[..., None, :]
        )
        out[a : a + k] = np.bincount(
            idx.ravel(), weights=weight.ravel(), minlength=k * h * w
        ).reshape(k, h, w)
    return out


@register_effect("blur", draws={"sigma_px": "uniform"})
def blur(
    state: SceneState, rng: np.random.Generator, *, sigma_px: float = 1.0
) -> SceneState:
    """Defocus: a Gaussian blur of ``sigma_px`` on every frame of every fingertip."""
    del rng
    name = "blur"
    s = _num(name, "sigma_px", sigma_px, lo=0.0)
    out = state
    for key in _frames(state, name):
        f = np.asarray(state.signals[key])
        if s > 0:
            f = gaussian_filter(f, sigma=(0.0, s, s), mode="nearest")
        out = out.with_signal(key, f)
    return out.with_truth(blur_sigma_px=s)


@register_effect("lighting_drift", draws={"gain": "uniform", "gradient": "uniform"})
def lighting_drift(
    state: SceneState,
    rng: np.random.Generator,
    *,
    gain: float = -0.2,
    gradient: float = 0.2,
) -> SceneState:
    """Lighting that drifts over the trial: the brightness changes by ``gain`` (a share,
    linear in time) and a linear gradient across the frame grows to ``gradient`` (a
    share of the brightness at the frame's edge) along a random direction. Both scale
    the image, so a dimmer gel also shows fainter markers."""
    name = "lighting_drift"
    g = _num(name, "gain", gain, lo=-0.95)
    grad = _num(name, "gradient", gradient, lo=0.0, hi=0.95)
    ang = rng.uniform(0.0, 2 * np.pi)
    out = state
    for key in _frames(state, name):
        f = np.asarray(state.signals[key])
        n, h, w = f.shape
        ramp = (np.arange(n) / max(n - 1, 1)).astype(np.float32)
        ry = (np.arange(h, dtype=np.float32) - h / 2) / (h / 2)
        rx = (np.arange(w, dtype=np.float32) - w / 2) / (w / 2)
        tilt = np.cos(ang) * rx[None, :] + np.sin(ang) * ry[:, None]
        factor = 1.0 + ramp[:, None, None] * (g + grad * tilt[None])
        out = out.with_signal(key, f * np.maximum(factor, 0.0))
    return out


__all__ = ["blur", "gel_shear", "lighting_drift", "marker_grid", "shake"]
