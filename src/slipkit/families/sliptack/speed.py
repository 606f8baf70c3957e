"""SlipTack: speed from the stick-slip frequency, acceleration from the nib deflection.

Follows the SlipTack paper (seed 000, ``docs/families/sliptack.md``):

* **dominant frequency** (Sec. IV-C, eqs. 6-7) -- :func:`dominant_frequency`: subtract a
  300-frame moving average, Hamming window, DFT (``numpy.fft.rfft``); the spectrum's local
  maxima (``scipy.signal.find_peaks``) at or below ``f_max`` are sorted by amplitude
  (``p(k, f_max)``, k = 1 the largest); ``f_i(f_max)`` is the mean over j = 1..10 of the
  mean frequency of the top j peaks (eq. 6, whose inner bound ``i`` we read as ``j``), and
  ``f_d`` the mean of ``f_i`` over ``f_max`` = 15, 16, ..., 40 Hz (26 values, eq. 7);
* **speed** -- :func:`speed_from_frequency` inverts ``f = 1 / (tau_stick + tau_slip)``
  (eq. 3) in the ``exact`` form (the integrated oscillator's period,
  :mod:`slipkit.families.sliptack.physics`) or the paper's form (``tau_stick = mu_s Fn / (k_l
  v0)``, ``tau_slip = pi / w0``); the speed is undefined (NaN) at and above the
  saturation frequency; :class:`StickSlipSpeed` runs it over a sliding window;
* **acceleration** -- :class:`DropAcceleration`: eq. 4 (``a = g - mu_k k_a (x - x0) /
  m_t``, calibrated by linear regression on the gross deflection, feature
  ``"deflection"``) or eq. 5 (the slope of the frequency-derived speed, feature
  ``"frequency_slope"``);
* **torsional slip** -- :class:`TorsionalSlipDetector`: RMS of the ~10 Hz band
  (Sec. IV-F, "effective frequency response ~10 Hz"), a :class:`StreamDetector`.

Every estimator has a batch form over whole recordings (``segments`` marks where one
ends) and a streaming form (``stream().update(sample)``) over a ring buffer of the last
``window`` samples; tests require both to agree. NaN policy: a value that cannot be
computed (warm-up, a flat window with no spectral peak, a frequency at or above
saturation, a NaN sample in the window) is NaN, never ``inf`` and never an exception.
"""

from __future__ import annotations

import math
import warnings
from collections import deque
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import uniform_filter1d
from scipy.optimize import minimize_scalar
from scipy.signal import find_peaks
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted, validate_data

from slipkit.baselines.base import segment_bounds
from slipkit.errors import SlipkitError, SlipkitWarning
from slipkit.families.sliptack.physics import (
    natural_frequency,
    saturation_frequency,
    slip_half_amplitude,
)

FloatArray = NDArray[np.float64]
Form = Literal["exact", "paper"]

#: The paper's f_max range for eq. 7 (Hz).
PAPER_F_MAX = (15.0, 40.0)

#: d ln(speed) / d ln(normal force) of eq. 3 inverted, both forms: the speed is the
#: stick length (proportional to Fn) times a function of the frequency alone, so a
#: normal force x % off gives a speed x % off.
SPEED_PER_FORCE = 1.0


class FixedNormalForceWarning(SlipkitWarning):
    """The speed uses one fixed normal force; its relative error passes 1:1 to the speed."""


# -- eqs. 6-7: dominant frequency of one window ------------------------------------------
def f_max_values(f_max_range: Sequence[float], step: float = 1.0) -> FloatArray:
    """The ``f_max`` values eq. 7 averages over (Hz): ``lo, lo + step, ..., hi``."""
    lo, hi = float(f_max_range[0]), float(f_max_range[1])
    if not 0.0 < lo <= hi or step <= 0:
        raise ValueError(
            f"f_max_range must be 0 < lo <= hi and step > 0; got {f_max_range}, {step}"
        )
    return np.arange(lo, hi + 1e-9 * step, step)


def gate_first_bin(nfft: int, detrend_frames: int) -> int:
    """First DFT bin of the ``min_peak_to_mean`` gate's band: ``ceil(2 nfft / detrend_frames)``, >= 1.

    Bin ``k`` is ``k rate / nfft`` Hz, so this is the first at or above twice the
    moving average's cutoff ``rate / detrend_frames`` (capped at ``nfft / 2``).
    """
    return int(min(max(1, -(-2 * int(nfft) // int(detrend_frames))), int(nfft) // 2))


def dominant_frequency(
    x: ArrayLike,
    rate_hz: float,
    *,
    detrend_frames: int = 300,
    n_peaks: int = 10,
    f_max_range: Sequence[float] = PAPER_F_MAX,
    f_max_step: float = 1.0,
    pad_factor: int = 1,
    min_peak_ratio: float = 0.0,
    harmonics: str = "keep",
    harmonic_tol: float = 0.03,
    interpolate: bool = False,
    min_peak_to_mean: float = 0.0,
) -> float:
    """Dominant stick-slip frequency ``f_d`` of one signal window (Hz), eqs. 6-7.

    Parameters
    ----------
    x : array_like (n,)
        The nib signal (any unit), in time order.
    rate_hz : float
        Sample rate (Hz).
    detrend_frames : int
        Length of the centred moving average subtracted first (frames; the paper: 300;
        clipped to ``n``). It removes the gross displacement.
    n_peaks : int
        Top peaks averaged by eq. 6 (the paper: 10).
    f_max_range : (float, float)
        Range of the spectrum limit ``f_max`` averaged by eq. 7 (Hz; the paper: 15-40).
    f_max_step : float
        Step of ``f_max`` (Hz; the paper: 1, giving 26 values).
    pad_factor : int
        Zero-padding of the DFT (1: none); finer frequency grid, same resolution.
    min_peak_ratio : float
        Peaks below this fraction of the largest spectral magnitude (DC excluded) are
        not counted (0: every local maximum, the paper's text). A slipkit addition: on a
        clean stick-slip signal the paper's top-10 average is dominated by noise peaks.
    harmonics : {"keep", "fundamental"}
        ``"fundamental"`` drops a counted peak at about ``m`` times (m >= 2) a lower
        counted peak: the stick-slip waveform's harmonics (a sawtooth's 2nd is ~0.5 of
        the fundamental, and can pass ``min_peak_ratio``) would otherwise be averaged
        in. ``"keep"``: the paper (every peak counts). A slipkit addition.
    harmonic_tol : float
        A peak in bin ``k_j`` is the ``m``-th harmonic of bin ``k_i`` when
        ``|k_j - m k_i| <= max(1, harmonic_tol m k_i)`` (bins, so batch and graph agree).
    interpolate : bool
        Refine each counted peak's frequency between bins by the parabola through the
        log magnitudes of its bin and its two neighbours (offset clipped to +-0.5 bin;
        none where a neighbour is 0). The ranking and the ``f_max`` limits still use
        the bin frequency. A slipkit addition: the DFT bin (``rate_hz / (n
        pad_factor)``, 1 Hz for 1000 samples at 1 kHz) is ~2 % of a 50 Hz frequency.
    min_peak_to_mean : float
        The "stick-slip oscillation present" gate: NaN unless the largest spectral
        power in the gate band is at least this times the band's mean power. The
        band is the bins from twice the detrend's cutoff (``2 rate_hz /
        detrend_frames``, :func:`gate_first_bin`) up: below it the moving average's
        repeated edge samples leave a low-frequency bump even in white noise.
        0: off (the paper: any local maximum makes a frequency, so a still object's
        noise spectrum reads as a speed). For Gaussian white noise the
        periodogram's bins are about exponential, so the largest of ``M`` reaches
        ``T`` times the mean with probability ~``M exp(-T)``: 20 keeps that near
        1e-6 for ``M`` = 500 bins. A slipkit addition.

    Returns
    -------
    float
        ``f_d`` in Hz; NaN when the window is shorter than 4 samples, holds a NaN, is
        flat after detrending, or has no spectral peak at or below the largest ``f_max``.
        An ``f_max`` with no peak below it is left out of eq. 7's mean.
    """
    xv = np.asarray(x, dtype=np.float64).reshape(-1)
    n = len(xv)
    if n < 4 or not np.isfinite(xv).all():
        return float("nan")
    trend = uniform_filter1d(xv, size=min(int(detrend_frames), n), mode="nearest")
    resid = xv - trend
    # A flat window: round-off in the moving average leaves ~1e-16 ripples whose
    # "peaks" are meaningless.
    if np.max(np.abs(resid)) <= 1e-12 * max(1.0, float(np.max(np.abs(xv)))):
        return float("nan")
    nfft = n * int(pad_factor)
    mag = np.abs(np.fft.rfft(resid * np.hamming(n), nfft))
    if min_peak_to_mean > 0.0:
        k0 = gate_first_bin(nfft, min(int(detrend_frames), n))
        power = mag[k0:] ** 2
        if float(np.max(power)) < float(min_peak_to_mean) * float(np.mean(power)):
            return float("nan")
    freqs = np.fft.rfftfreq(nfft, 1.0 / float(rate_hz))
    fmax = f_max_values(f_max_range, f_max_step)
    peaks, _ = find_peaks(mag)
    keep = (freqs[peaks] <= fmax[-1]) & (
        mag[peaks] >= float(min_peak_ratio) * float(np.max(mag[1:]))
    )
    peaks = peaks[keep]
    if harmonics == "fundamental":
        peaks = peaks[~harmonic_mask(peaks, harmonic_tol)]
    elif harmonics != "keep":
        raise ValueError(
            f"harmonics must be 'keep' or 'fundamental'; got {harmonics!r}"
        )
    if len(peaks) == 0:
        return float("nan")
    # p(k, .): peaks by amplitude, largest first (ties: lower frequency first).
    order = peaks[np.lexsort((freqs[peaks], -mag[peaks]))]
    pf = freqs[order]
    pv = (
        (order + parabolic_offset(mag, order)) * (freqs[1] - freqs[0])
        if interpolate
        else pf
    )
    ranks = np.arange(1, n_peaks + 1)
    f_i = np.full(len(fmax), np.nan)
    for m, limit in enumerate(fmax):
        p = pv[pf <= limit][:n_peaks]
        if len(p) == 0:
            continue
        top_j = np.cumsum(p) / np.arange(1, len(p) + 1)  # mean of the top j peaks
        # Fewer than n_peaks peaks: the top-j mean for j beyond them is the mean of all.
        f_i[m] = float(np.mean(top_j[np.minimum(ranks, len(p)) - 1]))
    return float(np.nanmean(f_i)) if np.isfinite(f_i).any() else float("nan")


def harmonic_relation(bins: ArrayLike, tol: float) -> NDArray[np.bool_]:
    """``rel[i, j]``: DFT bin ``bins[j]`` is the ``m``-th harmonic (m >= 2) of the lower
    bin ``bins[i]``, i.e. ``|k_j - m k_i| <= max(1, tol m k_i)`` with ``m = rint(k_j /
    k_i)``."""
    k = np.asarray(bins, dtype=np.float64)
    ki, kj = k[:, None], k[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        m = np.rint(kj / ki)
    near = np.abs(kj - m * ki) <= np.maximum(1.0, tol * m * ki)
    return np.asarray((m >= 2) & (ki < kj) & near)


def harmonic_mask(bins: ArrayLike, tol: float) -> NDArray[np.bool_]:
    """True for each DFT bin in ``bins`` that is a harmonic of a lower one in ``bins``
    (:func:`harmonic_relation`)."""
    return np.asarray(harmonic_relation(bins, tol).any(axis=0))


def parabolic_offset(mag: FloatArray, bins: ArrayLike) -> FloatArray:
    """Offset (bins, in [-0.5, 0.5]) of the parabola's vertex through the log magnitudes
    at ``bins - 1, bins, bins + 1``; 0 where a magnitude is 0 or the three are not a
    maximum."""
    k = np.asarray(bins, dtype=np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b, c = (np.log(mag[np.clip(k + d, 0, len(mag) - 1)]) for d in (-1, 0, 1))
        den = a - 2.0 * b + c
        off = 0.5 * (a - c) / den
    ok = np.isfinite(off) & (den < 0)
    return np.where(ok, np.clip(off, -0.5, 0.5), 0.0)


# -- eq. 3 inverted ------------------------------------------------------------------------
def _invert(f_hz: FloatArray, length_m: float, w0: float, form: str) -> FloatArray:
    """Speed (m/s) from frequency with the stick length ``length_m`` (d or mu_s Fn / k_l)."""
    f = np.asarray(f_hz, dtype=np.float64)
    out = np.full(f.shape, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        period = 1.0 / f
    if form == "paper":
        # 1/f = c / v + pi / w0  ->  v = c / (1/f - pi/w0), needs f < w0 / pi.
        rest = period - np.pi / w0
        ok = np.isfinite(f) & (f > 0) & (rest > 0)
        out[ok] = length_m / rest[ok]
        return out
    # exact: with theta = atan(v / (w0 d)) the period is w0 T = 2 cot(theta) + pi + 2 theta
    # (d cancels). With e = pi/2 - theta: 2 (tan e - e) = w0 T - 2 pi =: r > 0 below
    # saturation, tan e - e increasing on (0, pi/2). Solved by vectorised bisection
    # (hand-written: the same float operations for one value or many, so the streaming
    # and batch forms agree exactly; 80 halvings reach double precision).
    r = w0 * period - 2.0 * np.pi
    ok = np.isfinite(f) & (f > 0) & (r > 0)
    if not ok.any():
        return out
    target = 0.5 * r[ok]
    lo = np.zeros_like(target)
    hi = np.full_like(target, 0.5 * np.pi)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        above = np.tan(mid) - mid > target
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    e = 0.5 * (lo + hi)
    with np.errstate(divide="ignore"):
        v = w0 * length_m / np.tan(e)
    out[ok] = np.where(np.isfinite(v) & (e > 0), v, np.nan)
    return out


def speed_from_frequency(
    f_hz: ArrayLike,
    *,
    normal_force_N: float,
    mu_s: float,
    mu_k: float,
    M_kg: float,
    k_l_N_m: float,
    form: Form = "exact",
) -> FloatArray:
    """Pull speed ``v0`` (m/s) whose stick-slip frequency is ``f_hz`` (eq. 3 inverted).

    ``form="exact"`` inverts ``1 / f = 2 d / v0 + (pi + 2 atan(v0 / (w0 d))) / w0``
    (``d = (mu_s - mu_k) Fn / k_l``, the integrated oscillator's period);
    ``form="paper"`` inverts ``1 / f = mu_s Fn / (k_l v0) + pi / w0``. The period falls
    monotonically with ``v0`` towards ``tau_slip`` at infinite speed, so the inverse is
    unique below the saturation frequency (:func:`~slipkit.families.sliptack.physics.
    saturation_frequency`: ``w0 / (2 pi)`` exact, ``w0 / pi`` paper) and undefined at or
    above it. Returns NaN there, and for ``f <= 0`` or non-finite ``f``; close below
    saturation the speed grows without bound (``v0 ~ w0 d / (1.5 (w0 / f - 2 pi))^(1/3)``
    exact) and is ill-conditioned.
    """
    if form not in ("exact", "paper"):
        raise ValueError(f"form must be 'exact' or 'paper'; got {form!r}")
    w0 = float(natural_frequency(M_kg, k_l_N_m))
    length = (
        float(slip_half_amplitude(normal_force_N, mu_s, mu_k, k_l_N_m))
        if form == "exact"
        else mu_s * normal_force_N / k_l_N_m
    )
    f = np.asarray(f_hz, dtype=np.float64)
    return _invert(np.atleast_1d(f), length, w0, form).reshape(f.shape)


def _period(v: FloatArray, length_m: float, w0: float, form: str) -> FloatArray:
    """Stick-slip period (s) at speed ``v`` (m/s): eq. 3's ``tau_stick + tau_slip``."""
    if form == "paper":
        return length_m / v + np.pi / w0
    return 2.0 * length_m / v + (np.pi + 2.0 * np.arctan2(v, w0 * length_m)) / w0


# -- sliding windows ------------------------------------------------------------------------
class _FrequencyTrack:
    """Ring buffer of the last ``window`` samples; a new ``f_d`` every ``hop`` samples."""

    def __init__(self, est: StickSlipSpeed) -> None:
        self.est = est
        self.buf: deque[float] = deque(maxlen=int(est.window))
        self.force: deque[float] = deque(maxlen=int(est.window))
        self.n = 0
        self.f = float("nan")
        self.fn = float("nan")

    def reset(self) -> None:
        self.buf.clear()
        self.force.clear()
        self.n = 0
        self.f = float("nan")
        self.fn = float("nan")

    def update(self, value: float, force: float = math.nan) -> tuple[float, bool]:
        """Append one sample (and its normal force, N); return (current f_d in Hz,
        whether it was just recomputed). ``fn`` holds the window's mean force."""
        self.buf.append(float(value))
        self.force.append(float(force))
        self.n += 1
        w, h = int(self.est.window), int(self.est.hop)
        if self.n >= w and (self.n - w) % h == 0:
            self.f = self.est._window_frequency(np.fromiter(self.buf, np.float64, w))
            self.fn = float(np.mean(np.fromiter(self.force, np.float64, w)))
            return self.f, True
        return self.f, False


class StickSlipSpeed(RegressorMixin, BaseEstimator):
    """Object speed from the nib's stick-slip frequency (SlipTack eqs. 3, 6, 7).

    Every ``hop`` samples, eqs. 6-7 (:func:`dominant_frequency`) give ``f_d`` over the last
    ``window`` samples; eq. 3 inverted (:func:`speed_from_frequency`, ``form``) turns it into
    a speed, held until the next estimate. ``fit`` only calibrates: with
    ``calibrate=False`` it keeps the physical stick length from the parameters; with
    ``calibrate=True`` it fits the one unknown of eq. 3 (the stick length ``d`` for
    ``exact``, ``mu_s Fn / k_l`` for ``paper``) to the training samples by least squares on
    the period.

    Parameters
    ----------
    rate_hz : float
        Nib stream rate (Hz).
    window : int
        Samples per spectrum (frames); the frequency resolution is ``rate_hz / window``.
    hop : int
        Samples between estimates (frames).
    detrend_frames, n_peaks, f_max_range, f_max_step, pad_factor, min_peak_ratio
        As in :func:`dominant_frequency` (the paper: 300, 10, (15, 40) Hz, 1 Hz, 1, 0).
    harmonics, harmonic_tol, interpolate, min_peak_to_mean
        As in :func:`dominant_frequency` (the paper: "keep", -, False, 0).
    allow_aliasing : bool
        ``fit`` refuses (:class:`~slipkit.errors.SlipkitError`) a ``f_max_range``
        reaching the Nyquist limit ``rate_hz / 2``, and a rate whose Nyquist limit is
        below the saturation frequency (stick-slip frequencies up to saturation would
        fold back into the band) unless this is True; then ``alias_speed_mm_s_`` is the
        speed above which estimates are aliased.
    form : {"exact", "paper"}
        Which frequency-speed law is inverted.
    normal_force_N : float
        Normal load per nib (N): the fixed value used when ``normal_force="value"``, the
        reference of a calibrated stick length otherwise.
    normal_force : {"value", "input"}
        Where the normal force comes from: ``"value"`` (``normal_force_N``, one number
        for every trial; ``fit`` warns with :class:`FixedNormalForceWarning`: the speed
        is proportional to the normal force, so its relative error passes 1:1 to the
        speed) or ``"input"``: ``X`` has a second column, the measured normal force per
        nib (N), averaged over each analysis window.
    mu_s, mu_k : float
        Static and kinetic friction of the object on the skin.
    M_kg, k_l_N_m : float
        Nib mass (kg) and lateral stiffness (N/m); the paper's 1.4e-5 kg and 9.45 N/m.
    calibrate : bool
        Fit the stick length on the training samples (else use the physics).

    Attributes
    ----------
    stick_length_m_ : float
        ``d = (mu_s - mu_k) Fn / k_l`` (exact) or ``mu_s Fn / k_l`` (paper), in m, at
        ``Fn = normal_force_N``.
    w0_ : float
        Nib natural angular frequency (rad/s).
    saturation_hz_ : float
        Frequency at and above which the speed is undefined (Hz).
    nyquist_hz_ : float
        ``rate_hz / 2`` (Hz).
    alias_speed_mm_s_ : float
        Speed (mm/s) whose stick-slip frequency is the Nyquist limit: faster pulls
        alias (NaN when saturation lies below Nyquist: no speed aliases).
    normal_force_source_ : str
        ``"value 0.05 N"`` or ``"input column 1"``.
    speed_per_force_ : float
        Relative speed error per relative normal-force error (:data:`SPEED_PER_FORCE`,
        1: a force 30 % off gives a speed 30 % off).
    n_features_in_ : int
        Channels seen in ``fit`` (1, or 2 with ``normal_force="input"``).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "window": [Interval(Integral, 4, None, closed="left")],
        "hop": [Interval(Integral, 1, None, closed="left")],
        "detrend_frames": [Interval(Integral, 1, None, closed="left")],
        "n_peaks": [Interval(Integral, 1, None, closed="left")],
        "f_max_range": ["array-like"],
        "f_max_step": [Interval(Real, 0, None, closed="neither")],
        "pad_factor": [Interval(Integral, 1, None, closed="left")],
        "min_peak_ratio": [Interval(Real, 0, 1, closed="both")],
        "harmonics": [StrOptions({"keep", "fundamental"})],
        "harmonic_tol": [Interval(Real, 0, 1, closed="left")],
        "interpolate": ["boolean"],
        "min_peak_to_mean": [Interval(Real, 0, None, closed="left")],
        "allow_aliasing": ["boolean"],
        "form": [StrOptions({"exact", "paper"})],
        "normal_force_N": [Interval(Real, 0, None, closed="neither")],
        "normal_force": [StrOptions({"value", "input"})],
        "mu_s": [Interval(Real, 0, None, closed="neither")],
        "mu_k": [Interval(Real, 0, None, closed="neither")],
        "M_kg": [Interval(Real, 0, None, closed="neither")],
        "k_l_N_m": [Interval(Real, 0, None, closed="neither")],
        "calibrate": ["boolean"],
    }

    def __init__(
        self,
        *,
        rate_hz: float = 1000.0,
        window: int = 1000,
        hop: int = 10,
        detrend_frames: int = 300,
        n_peaks: int = 10,
        f_max_range: Sequence[float] = PAPER_F_MAX,
        f_max_step: float = 1.0,
        pad_factor: int = 1,
        min_peak_ratio: float = 0.0,
        harmonics: str = "keep",
        harmonic_tol: float = 0.03,
        interpolate: bool = False,
        min_peak_to_mean: float = 0.0,
        allow_aliasing: bool = False,
        form: str = "exact",
        normal_force_N: float = 0.05,
        normal_force: str = "value",
        mu_s: float = 0.55,
        mu_k: float = 0.45,
        M_kg: float = 1.4e-5,
        k_l_N_m: float = 9.45,
        calibrate: bool = False,
    ) -> None:
        self.rate_hz = rate_hz
        self.window = window
        self.hop = hop
        self.detrend_frames = detrend_frames
        self.n_peaks = n_peaks
        self.f_max_range = f_max_range
        self.f_max_step = f_max_step
        self.pad_factor = pad_factor
        self.min_peak_ratio = min_peak_ratio
        self.harmonics = harmonics
        self.harmonic_tol = harmonic_tol
        self.interpolate = interpolate
        self.min_peak_to_mean = min_peak_to_mean
        self.allow_aliasing = allow_aliasing
        self.form = form
        self.normal_force_N = normal_force_N
        self.normal_force = normal_force
        self.mu_s = mu_s
        self.mu_k = mu_k
        self.M_kg = M_kg
        self.k_l_N_m = k_l_N_m
        self.calibrate = calibrate

    # -- pieces --------------------------------------------------------------------
    def _window_frequency(self, x: FloatArray) -> float:
        return dominant_frequency(
            x,
            self.rate_hz,
            detrend_frames=self.detrend_frames,
            n_peaks=self.n_peaks,
            f_max_range=tuple(self.f_max_range),
            f_max_step=self.f_max_step,
            pad_factor=self.pad_factor,
            min_peak_ratio=self.min_peak_ratio,
            harmonics=self.harmonics,
            harmonic_tol=self.harmonic_tol,
            interpolate=self.interpolate,
            min_peak_to_mean=self.min_peak_to_mean,
        )

    def segment_frequency(self, x: ArrayLike) -> float:
        """``f_d`` of one whole signal segment (Hz), e.g. one steady pull (the paper)."""
        return self._window_frequency(np.asarray(x, dtype=np.float64).reshape(-1))

    def _recording_frequency(
        self, x: FloatArray, *, strict: bool = False, where: str = "the recording"
    ) -> FloatArray:
        """``f_d`` per sample of one recording (NaN in the warm-up), held between hops.

        ``strict``: a recording shorter than ``window`` is an error (it would be NaN
        throughout), naming the window and the recording's length.
        """
        return self._recording_windows(x, x, strict=strict, where=where)[0]

    def _recording_windows(
        self, x: FloatArray, force: FloatArray, *, strict: bool, where: str
    ) -> tuple[FloatArray, FloatArray]:
        """(``f_d``, window-mean ``force``) per sample of one recording, held between hops."""
        n, w, h = len(x), int(self.window), int(self.hop)
        out, fn = np.full(n, np.nan), np.full(n, np.nan)
        if n < w:
            if strict:
                rate = float(self.rate_hz)
                raise SlipkitError(
                    f"{type(self).__name__}: window {w} samples ({w / rate:g} s at "
                    f"{rate:g} Hz) is longer than {where} ({n} samples, {n / rate:g} s): "
                    "no frequency could be estimated; use a window of at most "
                    f"{n} samples"
                )
            return out, fn
        ends = np.arange(w - 1, n, h)  # sample index at which each estimate is made
        views = sliding_window_view(x, w)[ends - (w - 1)]
        vals = np.array(
            [self._window_frequency(np.ascontiguousarray(v)) for v in views]
        )
        fviews = sliding_window_view(force, w)[ends - (w - 1)]
        fvals = np.array([float(np.mean(np.ascontiguousarray(v))) for v in fviews])
        idx = np.searchsorted(ends, np.arange(n), side="right") - 1
        have = idx >= 0
        out[have] = vals[idx[have]]
        fn[have] = fvals[idx[have]]
        return out, fn

    @property
    def _n_channels(self) -> int:
        return 2 if self.normal_force == "input" else 1

    def _check(self, X: ArrayLike, *, reset: bool) -> FloatArray:
        Xv = np.asarray(
            validate_data(
                self, X, reset=reset, dtype=np.float64, ensure_all_finite=False
            )
        )
        if Xv.shape[1] != self._n_channels:
            what = (
                "the nib signal and the normal force (N), normal_force='input'"
                if self._n_channels == 2
                else "the nib signal; normal_force='value'"
            )
            raise ValueError(
                f"{type(self).__name__} reads {self._n_channels} channel(s) ({what}); "
                f"X has {Xv.shape[1]}"
            )
        return Xv

    def _check_rate(self) -> None:
        """Refuse a band the stream's Nyquist limit cannot carry (SlipkitError)."""
        rate = float(self.rate_hz)
        nyq = 0.5 * rate
        self.nyquist_hz_ = nyq
        hi = float(self.f_max_range[1])
        if hi >= nyq:
            raise SlipkitError(
                f"{type(self).__name__}: f_max_range {list(self.f_max_range)} Hz reaches "
                f"the Nyquist limit {nyq:g} Hz of rate_hz {rate:g} Hz: frequencies "
                f"above {nyq:g} Hz fold back (alias) into the band; use an f_max below "
                f"{nyq:g} Hz or a stream sampled above {2 * hi:g} Hz"
            )
        alias = math.nan
        if self.saturation_hz_ >= nyq:
            with np.errstate(divide="ignore"):
                alias = float(
                    1e3
                    * _invert(
                        np.array([nyq]), self.stick_length_m_, self.w0_, self.form
                    )[0]
                )
            if not self.allow_aliasing:
                raise SlipkitError(
                    f"{type(self).__name__}: at rate_hz {rate:g} Hz (Nyquist "
                    f"{nyq:g} Hz) the stick-slip band up to saturation "
                    f"({self.saturation_hz_:.1f} Hz) aliases: pulls faster than "
                    f"{alias:.3g} mm/s would read as lower frequencies (wrong speeds, no "
                    "warning); sample at >= "
                    f"{2 * self.saturation_hz_:.0f} Hz or set allow_aliasing=true"
                )
        self.alias_speed_mm_s_ = alias

    def _physics_length(self) -> float:
        if self.form == "exact":
            return float(
                slip_half_amplitude(
                    self.normal_force_N, self.mu_s, self.mu_k, self.k_l_N_m
                )
            )
        return self.mu_s * self.normal_force_N / self.k_l_N_m

    # -- sklearn -------------------------------------------------------------------
    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> StickSlipSpeed:
        """Calibrate on recordings ``X`` (n_samples, 1) with true speeds ``y`` (mm/s).

        Samples with NaN ``y`` (or ``y <= 0``) are ignored by the calibration.
        """
        self._validate_params()
        if self.mu_k >= self.mu_s:
            raise ValueError(
                f"need mu_k < mu_s; got mu_s={self.mu_s}, mu_k={self.mu_k}"
            )
        Xv = self._check(X, reset=True)
        yv = np.asarray(y, dtype=np.float64).reshape(-1)
        if yv.shape != (len(Xv),):
            raise ValueError(f"y must have shape ({len(Xv)},); got {yv.shape}")
        f_max_values(self.f_max_range, self.f_max_step)  # checks the range
        self.w0_ = float(natural_frequency(self.M_kg, self.k_l_N_m))
        self.saturation_hz_ = float(
            saturation_frequency(self.M_kg, self.k_l_N_m, form=self.form)  # type: ignore[arg-type]
        )
        self.stick_length_m_ = self._physics_length()
        self._check_rate()
        self.speed_per_force_ = SPEED_PER_FORCE
        if self.normal_force == "input":
            self.normal_force_source_ = "input column 1"
        else:
            self.normal_force_source_ = f"value {float(self.normal_force_N):g} N"
            warnings.warn(
                f"{type(self).__name__}: one fixed normal force "
                f"({float(self.normal_force_N):g} N per nib) for every trial; the speed "
                "is proportional to it (speed_per_force_ = 1): a force 30 % off gives "
                "a speed 30 % off. Feed the measured force (normal_force='input') "
                "when it varies",
                FixedNormalForceWarning,
                stacklevel=2,
            )
        if self.calibrate:
            f = self._frequencies(Xv, segments)
            ok = np.isfinite(f) & (f > 0) & np.isfinite(yv) & (yv > 0)
            if not ok.any():
                raise ValueError(
                    "calibrate=True needs samples with a frequency estimate and a "
                    "positive true speed; none found (recordings shorter than window?)"
                )
            period, v = 1.0 / f[ok], yv[ok] * 1e-3

            def loss(log_len: float) -> float:
                resid = period - _period(v, float(np.exp(log_len)), self.w0_, self.form)
                return float(np.mean(resid * resid))

            ref = np.log(self.stick_length_m_)
            res = minimize_scalar(
                loss,
                bounds=(ref - 6.0, ref + 6.0),
                method="bounded",
                options={"xatol": 1e-10},
            )
            self.stick_length_m_ = float(np.exp(res.x))
        return self

    def _windows(
        self, Xv: FloatArray, segments: ArrayLike | None
    ) -> tuple[FloatArray, FloatArray]:
        f, fn = np.empty(len(Xv)), np.empty(len(Xv))
        bounds = segment_bounds(len(Xv), segments)
        for k, (a, b) in enumerate(bounds):
            where = "the recording" if len(bounds) == 1 else f"recording {k} (0-based)"
            force = Xv[a:b, 1] if Xv.shape[1] > 1 else Xv[a:b, 0]
            f[a:b], fn[a:b] = self._recording_windows(
                Xv[a:b, 0], force, strict=True, where=where
            )
        return f, fn

    def _frequencies(self, Xv: FloatArray, segments: ArrayLike | None) -> FloatArray:
        return self._windows(Xv, segments)[0]

    def frequency(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FloatArray:
        """Dominant frequency ``f_d`` per sample (Hz; NaN in the warm-up).

        Raises :class:`~slipkit.errors.SlipkitError` when a recording is shorter than
        ``window`` (it would be NaN throughout)."""
        check_is_fitted(self, "stick_length_m_")
        return self._frequencies(self._check(X, reset=False), segments)

    def _force_scale(self, fn: ArrayLike) -> FloatArray | float:
        """Speed factor of the window's mean normal force: ``Fn / normal_force_N``."""
        if self.normal_force != "input":
            return 1.0
        return np.asarray(fn, dtype=np.float64) / float(self.normal_force_N)

    def speed_from_frequency(self, f_hz: ArrayLike) -> FloatArray:
        """Eq. 3 inverted with the fitted stick length: speed (mm/s), NaN at saturation."""
        check_is_fitted(self, "stick_length_m_")
        f = np.atleast_1d(np.asarray(f_hz, dtype=np.float64))
        return 1e3 * _invert(f, self.stick_length_m_, self.w0_, self.form)

    def frequency_from_speed(
        self, v_mm_s: ArrayLike, normal_force_N: float | None = None
    ) -> FloatArray:
        """Eq. 3 with the fitted stick length: frequency (Hz) at speed ``v`` (mm/s).

        ``normal_force_N`` (N): the stick length scaled to this normal force (the
        fitted one is at ``normal_force_N`` of the parameters); None: as fitted."""
        check_is_fitted(self, "stick_length_m_")
        v = 1e-3 * np.asarray(v_mm_s, dtype=np.float64)
        length = self.stick_length_m_
        if normal_force_N is not None:
            length = length * float(normal_force_N) / float(self.normal_force_N)
        with np.errstate(divide="ignore"):
            return 1.0 / _period(v, length, self.w0_, self.form)

    def predict(self, X: ArrayLike, *, segments: ArrayLike | None = None) -> FloatArray:
        """Speed per sample (mm/s); NaN in the warm-up, without a peak, or at saturation.

        With ``normal_force="input"`` the speed scales with the window's mean normal
        force (eq. 3: the stick length is proportional to ``Fn``)."""
        check_is_fitted(self, "stick_length_m_")
        f, fn = self._windows(self._check(X, reset=False), segments)
        return self.speed_from_frequency(f) * self._force_scale(fn)

    def stream(self) -> SpeedStream:
        """The sample-by-sample form: ``update(sample) -> (f_d Hz, speed mm/s)``."""
        check_is_fitted(self, "stick_length_m_")
        return SpeedStream(self)

    def __sklearn_tags__(self) -> Any:
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True
        return tags


class SpeedStream:
    """Streaming :class:`StickSlipSpeed`: O(window) work every ``hop`` samples, O(1) else."""

    def __init__(self, est: StickSlipSpeed) -> None:
        self.est = est
        self.track = _FrequencyTrack(est)
        self.speed = float("nan")

    def reset(self) -> None:
        """Forget all state (a new recording starts)."""
        self.track.reset()
        self.speed = float("nan")

    def update(self, sample: ArrayLike) -> tuple[float, float]:
        """Feed one sample ((1,) / scalar, or (nib, normal force N) with
        ``normal_force="input"``); return (frequency Hz, speed mm/s) now."""
        row = np.asarray(sample, dtype=np.float64).reshape(-1)
        x = float(row[0])
        force = float(row[1]) if len(row) > 1 else x
        f, new = self.track.update(x, force)
        if new:  # invert only when a new estimate was made (every hop samples)
            scale = float(self.est._force_scale(self.track.fn))
            self.speed = float(self.est.speed_from_frequency(f)[0]) * scale
        return f, self.speed


__all__ = [
    "PAPER_F_MAX",
    "SPEED_PER_FORCE",
    "FixedNormalForceWarning",
    "StickSlipSpeed",
    "dominant_frequency",
    "f_max_values",
    "harmonic_mask",
    "harmonic_relation",
    "parabolic_offset",
    "speed_from_frequency",
]
