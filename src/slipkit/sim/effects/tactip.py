"""TacTip effects: skin stretch, snap-back at slip onset, post-slip sliding, pin
detection jitter and missing pins (James, Pestell, Lepora 2018, RA-L 3(4)).

Every effect acts on the ``pins`` signal, shape (T, N, 2) in mm, aligned with
``time["pins"]``; the contact physics is evaluated at those times from the trial's
:class:`~slipkit.sim.scenes.tactip.TacTipTrial` (``truth["tactip"]``).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from slipkit.physics.tactip import mindlin_stretch
from slipkit.sim.core import SceneState, SimulationError, register_effect
from slipkit.sim.effects.common import white_noise
from slipkit.sim.scenes.tactip import TacTipTrial


def _trial(state: SceneState, effect: str) -> TacTipTrial:
    trial = state.truth.get("tactip")
    if not isinstance(trial, TacTipTrial):
        raise SimulationError(
            f"effect {effect!r} needs a TacTip scene (truth['tactip']); this scene has none"
        )
    return trial


def _shift(pins: np.ndarray, amount: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Move each pin by ``amount`` (T, N) mm along the unit vector ``direction``."""
    return pins + amount[..., None] * direction


@register_effect("skin_stretch")
def skin_stretch(state: SceneState, rng: np.random.Generator) -> SceneState:
    """Pre-slip skin stretch: pins drift slowly in the load direction as the grip falls.

    The weight ``m g`` is a constant tangential load while the retraction lowers the
    normal load ``P``; the contact's tangential displacement grows by Cattaneo-Mindlin
    partial slip (Johnson, *Contact Mechanics*, 1985, Sec. 7.2),
    ``u(t) = u_on ρ^(-2/3) [1 - (1 - ρ)^(2/3)]`` with ``ρ = m g / (μ_s P)``, reaching
    ``u_on = m g / k_t`` at the onset and held there afterwards. Each pin moves by
    ``u(t) w_i(t)`` (``w`` the contact weight). Paper, Sec. III-B1: "the surface of
    the TacTip stretches downwards due to the object weight".
    """
    del rng  # deterministic
    tr = _trial(state, "skin_stretch")
    t = state.time["pins"]
    pins = state.signal("pins", "skin_stretch")
    frac = np.where(t < tr.onset_s, mindlin_stretch(tr.load_ratio(t)), 1.0)
    u = tr.stretch_mm * frac[:, None] * tr.weights(t)
    return state.with_signal("pins", _shift(pins, u, tr.load_dir))


@register_effect("snap_back")
def snap_back(
    state: SceneState, rng: np.random.Generator, *, tau_s: float = 0.02
) -> SceneState:
    """Snap-back at onset: the stretched skin springs back against the load.

    Paper, Sec. III-B1: at slip "the coefficient of friction changes from a static to
    kinetic value ... the elastic force from the stretched sensor surface causes it
    to move back towards its non-deformed shape, shifting the pins upwards"; the
    velocity spike is present in all pins (Sec. IV-A, Fig. 7). Model (assumption:
    first-order relaxation): for ``τ = t - t_on >= 0`` the stretch relaxes from
    ``u_on`` towards the kinetic level ``u_on μ_k F_n(t) / (m g)``,
    ``Δu_i(t) = u_on w_i(t) [1 - μ_k F_n(t) / (m g)] (1 - exp(-τ / tau_s))``,
    against the load direction. ``tau_s`` (s) sets the spike's decay.
    """
    del rng  # deterministic
    if not tau_s > 0:
        raise SimulationError(f"effect 'snap_back': tau_s must be > 0 s; got {tau_s!r}")
    tr = _trial(state, "snap_back")
    t = state.time["pins"]
    pins = state.signal("pins", "snap_back")
    tau = t - tr.onset_s
    kinetic = np.clip(tr.mu_k * tr.normal_force(t) / tr.weight_N, 0.0, 1.0)
    release = np.where(
        tau >= 0, (1.0 - kinetic) * -np.expm1(-np.clip(tau, 0.0, None) / tau_s), 0.0
    )
    u = tr.stretch_mm * release[:, None] * tr.weights(t)
    return state.with_signal("pins", _shift(pins, u, -tr.load_dir))


@register_effect("slip_sliding")
def slip_sliding(
    state: SceneState,
    rng: np.random.Generator,
    *,
    sigma_mm: float = 0.03,
    corr_s: float = 0.02,
    ramp_s: float = 0.03,
) -> SceneState:
    """Post-slip sliding: the object dragging over the skin shakes the pins incoherently.

    Observation (paper, Fig. 4(c) and Sec. III-B3): five frames after onset "the slip
    signal has already become very noisy"; the clean signal lasts about 4 frames.
    Model (assumption): after the onset each pin gets an independent AR(1) displacement
    per axis, ``x_k = φ x_(k-1) + e_k`` with ``φ = exp(-Δt / corr_s)`` and stationary
    standard deviation ``sigma_mm``, scaled by the pin's contact weight and by
    ``1 - exp(-τ / ramp_s)`` so it builds up over the first frames.
    """
    if sigma_mm < 0 or not corr_s > 0 or not ramp_s > 0:
        raise SimulationError(
            f"effect 'slip_sliding': need sigma_mm >= 0, corr_s > 0, ramp_s > 0; "
            f"got {sigma_mm!r}, {corr_s!r}, {ramp_s!r}"
        )
    tr = _trial(state, "slip_sliding")
    t = state.time["pins"]
    pins = state.signal("pins", "slip_sliding")
    after = np.flatnonzero(t >= tr.onset_s)
    if len(after) == 0:
        return state
    ta = t[after]
    dt = float(np.median(np.diff(t))) if len(t) > 1 else corr_s
    phi = float(np.exp(-dt / corr_s))
    drive = rng.normal(0.0, sigma_mm, size=(len(after), *pins.shape[1:]))
    drive[1:] *= np.sqrt(1.0 - phi**2)  # stationary from the first frame
    ar = lfilter([1.0], [1.0, -phi], drive, axis=0)
    envelope = -np.expm1(-(ta - tr.onset_s) / ramp_s)[:, None] * tr.weights(ta)
    out = np.array(pins, dtype=np.float64, copy=True)
    out[after] += ar * envelope[..., None]
    return state.with_signal("pins", out)


@register_effect("pin_jitter")
def pin_jitter(
    state: SceneState, rng: np.random.Generator, *, sigma_mm: float
) -> SceneState:
    """Pin detection jitter: independent Gaussian noise (s.d. ``sigma_mm``) on each x and y.

    Observation: pin centres come from thresholding and contour detection on each
    camera frame (paper, Sec. III-A4), so each centre carries an independent
    localisation error per frame. Applies the common ``white_noise`` to ``pins``.
    """
    if sigma_mm < 0:
        raise SimulationError(
            f"effect 'pin_jitter': sigma_mm must be >= 0; got {sigma_mm!r}"
        )
    state.signal("pins", "pin_jitter")
    return white_noise(state, rng, target="pins", sigma=sigma_mm)


@register_effect("missing_pins")
def missing_pins(
    state: SceneState, rng: np.random.Generator, *, probability: float
) -> SceneState:
    """Missing pins: a pin is not detected in a frame with ``probability``; both its
    coordinates become NaN for that frame.

    Observation: contour detection (paper, Sec. III-A4) can miss a pin in a frame
    (occlusion, glare); assumption: misses are independent across pins and frames.
    """
    if not 0.0 <= probability <= 1.0:
        raise SimulationError(
            f"effect 'missing_pins': probability must be in [0, 1]; got {probability!r}"
        )
    pins = np.array(state.signal("pins", "missing_pins"), dtype=np.float64, copy=True)
    miss = rng.random(pins.shape[:2]) < probability
    pins[miss] = np.nan
    return state.with_signal("pins", pins)
