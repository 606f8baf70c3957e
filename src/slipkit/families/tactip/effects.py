"""TacTip effects: skin stretch, partial-slip creep, snap-back at slip onset, post-slip
sliding, pin detection jitter and missing pins (James, Pestell, Lepora 2018, RA-L 3(4)).

Every effect acts on the ``pins`` signal, shape (T, N, 2) in mm, aligned with
``time["pins"]``; the contact physics is evaluated at those times from the trial's
:class:`~slipkit.families.tactip.scene.TacTipTrial` (``truth["tactip"]``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.signal import lfilter

from slipkit.families.tactip.physics import contact_semi_axes, mindlin_stretch
from slipkit.sim.core import SceneState, SimulationError, register_effect
from slipkit.sim.effects.common import white_noise

if TYPE_CHECKING:
    from slipkit.families.tactip.scene import TacTipTrial


def _trial(state: SceneState, effect: str) -> TacTipTrial:
    # imported here: the scene module imports slipkit.sim, whose import registers these
    # effects (slipkit.families.PLUGIN_MODULES), so a module-level import would be circular
    from slipkit.families.tactip.scene import TacTipTrial

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


@register_effect("snap_back", draws={"tau_s": "uniform"})
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


@register_effect(
    "slip_sliding",
    draws={"sigma_mm": "log", "corr_s": "uniform", "ramp_s": "uniform"},
)
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


@register_effect("pin_jitter", draws={"sigma_mm": "log"})
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


@register_effect("missing_pins", draws={"probability": "uniform"})
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


@register_effect("missing_pin_frames", draws={"frame_probability": "uniform"})
def missing_pin_frames(
    state: SceneState,
    rng: np.random.Generator,
    *,
    frame_probability: float,
    count: Any = (1, 5),
) -> SceneState:
    """Frames with a few undetected pins: with ``frame_probability`` a frame loses
    ``k`` pins (NaN), ``k`` uniform on the integers of ``count`` = ``[lo, hi]``, the
    pins chosen uniformly without replacement.

    Observation (an independent signal generator): 1-5 NaN pins in ~3 % of
    frames, i.e. misses come in bursts within a frame (a glare patch, a blurred frame)
    rather than independently per pin as in ``missing_pins``. Assumption: affected
    frames are independent of each other and of the motion.
    """
    name = "missing_pin_frames"
    if not 0.0 <= frame_probability <= 1.0:
        raise SimulationError(
            f"effect {name!r}: frame_probability must be in [0, 1]; got {frame_probability!r}"
        )
    lo, hi = _count_range(count, name)
    pins = np.array(state.signal("pins", name), dtype=np.float64, copy=True)
    n_frames, n_pins = pins.shape[:2]
    hit = np.flatnonzero(rng.random(n_frames) < frame_probability)
    if len(hit) == 0:
        return state.with_signal("pins", pins)
    k = np.minimum(rng.integers(lo, hi + 1, size=len(hit)), n_pins)
    # Rank of each pin in a random permutation per frame: the k lowest are lost.
    ranks = rng.random((len(hit), n_pins)).argsort(axis=1).argsort(axis=1)
    lost = ranks < k[:, None]
    sub = pins[hit]
    sub[lost] = np.nan
    pins[hit] = sub
    return state.with_signal("pins", pins)


def _count_range(value: Any, effect: str) -> tuple[int, int]:
    """A whole number or ``[lo, hi]`` of whole numbers >= 0."""
    items = list(value) if isinstance(value, list | tuple) else [value, value]
    ok = len(items) == 2 and all(
        isinstance(v, int | float) and float(v).is_integer() and v >= 0 for v in items
    )
    if not ok or items[1] < items[0]:
        raise SimulationError(
            f"effect {effect!r}: count must be a whole number or [lo, hi] with "
            f"0 <= lo <= hi; got {value!r}"
        )
    return int(items[0]), int(items[1])


@register_effect("mindlin_creep", draws={"amplitude_mm": "uniform"})
def mindlin_creep(
    state: SceneState, rng: np.random.Generator, *, amplitude_mm: float
) -> SceneState:
    """Partial-slip creep before onset: micro-slip spreading inward from the contact edge.

    Cattaneo-Mindlin (Johnson, *Contact Mechanics*, 1985, Sec. 7.2): under a tangential
    load ``Q`` below ``μ_s P`` the contact sticks inside a radius ``c`` and slips in the
    annulus ``c < r < a``, with ``c / a = (1 - ρ)^(1/3)``, ``ρ = Q / (μ_s P)`` (the
    trial's ``load_ratio``). As the grip falls ``ρ`` grows to 1, the stick zone
    shrinks to nothing and gross slip starts. Pin ``i`` at normalised elliptic radius
    ``q_i = sqrt((x/a_x)^2 + (y/a_y)^2)`` creeps along the load direction by
    ``A ρ(t) h_i(t) w_i(t)``, ``h = clip((q^2 - c^2) / (1 - c^2), 0, 1)`` (0 in the
    stick zone, 1 at and beyond the edge), ``w`` the contact weight; frozen at its
    onset value (``ρ = 1``, ``c = 0``) afterwards. ``A = amplitude_mm`` (mm) is the
    creep of an edge pin at onset. Observation: an independent signal generator
    shows such a creep before onset; the profile ``h`` is an assumption (Johnson's
    annulus slip grows from 0 at ``c`` to its largest at ``a``).
    """
    del rng  # deterministic
    name = "mindlin_creep"
    if not (np.isfinite(amplitude_mm) and amplitude_mm >= 0):
        raise SimulationError(
            f"effect {name!r}: amplitude_mm must be >= 0; got {amplitude_mm!r}"
        )
    tr = _trial(state, name)
    t = state.time["pins"]
    pins = state.signal("pins", name)
    tc = np.minimum(t, tr.onset_s)  # frozen at the onset
    rho = np.clip(tr.load_ratio(tc), 0.0, 1.0)
    rho = np.where(t >= tr.onset_s, 1.0, rho)
    c2 = ((1.0 - rho) ** (1.0 / 3.0))[:, None] ** 2
    ax, ay = contact_semi_axes(tr.indentation(tc), tr.object_radius, tr.tip_radius_mm)
    x, y = tr.rest_xy[None, :, 0], tr.rest_xy[None, :, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        q2 = (x / ax[:, None]) ** 2 + (y / ay[:, None]) ** 2
        h = np.clip((q2 - c2) / (1.0 - c2), 0.0, 1.0)
    h = np.where(c2 < 1.0, np.nan_to_num(h, nan=0.0), 0.0)
    u = amplitude_mm * rho[:, None] * h * tr.weights(tc)
    return state.with_signal("pins", _shift(pins, u, tr.load_dir))
