"""A learned SlipTack speed regressor on spectral features of the nib signal.

The analytic estimator (:class:`slipkit.families.sliptack.speed.StickSlipSpeed`) finds the
dominant stick-slip frequency of a window and inverts eq. 3 of the paper.
:class:`SpectralSpeedRegressor` learns speed from the same window's spectrum instead:
every ``hop`` samples, the last ``window`` samples (linearly detrended, Hamming) give a
power spectrum, reduced to

* the log relative power in ``n_bands`` log-spaced bands over ``band_hz``,
* the ``n_peaks`` strongest spectral peaks' frequencies (Hz, strongest first),
* the analytic estimator's dominant frequency ``f_d`` (Hz) of the same window
  (``f_d_feature=True``, the default; False leaves it out: its exported graph is then
  about 40 % of the cost, ``benchmarks/bench_spectral_export.py``),

and a regressor (``model``: ``"gbr"``, scikit-learn's histogram gradient boosting,
seeded; or ``"ridge"`` on standardised features) maps them to the speed (mm/s). The
prediction is held between hops (as the analytic estimator's) and NaN in a recording's
first ``window - 1`` samples.

The SlipTack speed task (:class:`~slipkit.families.sliptack.task.SlipTackSpeed`) also
reads the physics of its estimator for its diagnostics (the pull's ``f_d``, eq. 3's
frequency at the true speed, the stick length): those come from the internal analytic
estimator ``physics_`` fitted on the same trials (its ``mu_s`` / ``mu_k`` set by the
task per material), so the task's frequency columns are the analytic ones and only the
speed is learned. Exported by :mod:`slipkit.families.sliptack.export.spectral` (the features as ONNX ops,
the regressor through skl2onnx).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from scipy.signal import detrend, find_peaks
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.linear_model import Ridge
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from slipkit.baselines.base import segment_bounds
from slipkit.errors import SlipkitError
from slipkit.families.sliptack.speed import FixedNormalForceWarning, StickSlipSpeed

FloatArray = NDArray[np.float64]


class SpectralSpeedRegressor(RegressorMixin, BaseEstimator):
    """Speed (mm/s) from band powers and peak frequencies of the nib window (see module doc).

    Parameters
    ----------
    rate_hz : float
        Nib stream rate (Hz).
    window, hop : int
        Samples per spectrum; samples between spectra.
    n_bands : int
        Log-spaced bands over ``band_hz``.
    band_hz : sequence of 2 float
        Band range (Hz).
    n_peaks : int
        Strongest peaks whose frequencies are features.
    model : {"gbr", "ridge"}
        Histogram gradient boosting (``max_iter``, ``random_state``) or ridge (``alpha``).
    max_iter : int
        Boosting iterations.
    alpha : float
        Ridge strength.
    random_state : int
        Seed of the boosting.
    mu_s, mu_k : float
        Friction of the internal analytic estimator (set per material by the task).
    f_d_feature : bool
        Whether ``f_d`` is a feature (the last column). The internal analytic
        estimator is fitted either way (the task's diagnostics read it).

    Attributes
    ----------
    regressor_ : estimator
        The fitted feature -> speed regressor.
    physics_ : StickSlipSpeed
        The analytic estimator fitted on the same data (``f_d`` feature, diagnostics).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "rate_hz": [Interval(Real, 0, None, closed="neither")],
        "window": [Interval(Integral, 8, None, closed="left")],
        "hop": [Interval(Integral, 1, None, closed="left")],
        "n_bands": [Interval(Integral, 1, None, closed="left")],
        "band_hz": ["array-like"],
        "n_peaks": [Interval(Integral, 0, None, closed="left")],
        "model": [StrOptions({"gbr", "ridge"})],
        "max_iter": [Interval(Integral, 1, None, closed="left")],
        "alpha": [Interval(Real, 0, None, closed="left")],
        "random_state": [Interval(Integral, 0, None, closed="left")],
        "mu_s": [Interval(Real, 0, None, closed="neither")],
        "mu_k": [Interval(Real, 0, None, closed="neither")],
        "f_d_feature": ["boolean"],
    }

    def __init__(
        self,
        *,
        rate_hz: float = 1000.0,
        window: int = 1000,
        hop: int = 10,
        n_bands: int = 16,
        band_hz: Sequence[float] = (5.0, 250.0),
        n_peaks: int = 3,
        model: str = "gbr",
        max_iter: int = 200,
        alpha: float = 1.0,
        random_state: int = 0,
        mu_s: float = 0.55,
        mu_k: float = 0.45,
        f_d_feature: bool = True,
    ) -> None:
        self.rate_hz = rate_hz
        self.window = window
        self.hop = hop
        self.n_bands = n_bands
        self.band_hz = band_hz
        self.n_peaks = n_peaks
        self.model = model
        self.max_iter = max_iter
        self.alpha = alpha
        self.random_state = random_state
        self.mu_s = mu_s
        self.mu_k = mu_k
        self.f_d_feature = f_d_feature

    # -- what the SlipTack task reads of its estimator ----------------------------------
    @property
    def form(self) -> str:
        """How speed is found (the task records it): learned, not an eq. 3 form."""
        return "learned (spectral features)"

    @property
    def stick_length_m_(self) -> float:
        """The internal analytic estimator's stick length (m)."""
        check_is_fitted(self, "physics_")
        return float(self.physics_.stick_length_m_)

    @property
    def saturation_hz_(self) -> float:
        """The internal analytic estimator's saturation frequency (Hz)."""
        check_is_fitted(self, "physics_")
        return float(self.physics_.saturation_hz_)

    def segment_frequency(self, x: ArrayLike) -> float:
        """``f_d`` of one whole segment (Hz), by the internal analytic estimator."""
        check_is_fitted(self, "physics_")
        return self.physics_.segment_frequency(x)

    def frequency(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FloatArray:
        """Dominant frequency ``f_d`` per sample (Hz), by the internal analytic estimator."""
        check_is_fitted(self, "physics_")
        return self.physics_.frequency(self._check(X)[:, :1], segments=segments)

    def frequency_from_speed(
        self, v_mm_s: ArrayLike, normal_force_N: float | None = None
    ) -> FloatArray:
        """Eq. 3 frequency (Hz) at speed ``v`` (mm/s), by the internal analytic estimator."""
        check_is_fitted(self, "physics_")
        return self.physics_.frequency_from_speed(v_mm_s, normal_force_N)

    # -- features -----------------------------------------------------------------------
    def _physics(self) -> StickSlipSpeed:
        return StickSlipSpeed(
            rate_hz=float(self.rate_hz),
            window=int(self.window),
            hop=int(self.hop),
            f_max_range=[15.0, 100.0],
            min_peak_ratio=0.6,
            harmonics="fundamental",
            interpolate=True,
            mu_s=float(self.mu_s),
            mu_k=float(self.mu_k),
        )

    def _check(self, X: ArrayLike) -> FloatArray:
        A = np.asarray(X, dtype=np.float64)
        if A.ndim == 1:
            A = A[:, None]
        if A.ndim != 2 or A.shape[1] < 1:
            raise SlipkitError(
                f"SpectralSpeedRegressor: X must be (n_samples, 1) nib samples; got {A.shape}"
            )
        return A

    def features(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> tuple[FloatArray, NDArray[np.int64]]:
        """Features of every full window (rows) and the sample index each one ends at.

        Returns
        -------
        F : ndarray of shape (n_windows, n_bands + n_peaks + f_d_feature)
        ends : ndarray of int, shape (n_windows,)
        """
        A = self._check(X)
        w, hop, rate = int(self.window), int(self.hop), float(self.rate_hz)
        freqs = np.fft.rfftfreq(w, 1.0 / rate)
        lo, hi = (float(b) for b in self.band_hz)
        edges = np.geomspace(lo, min(hi, rate / 2), int(self.n_bands) + 1)
        band = np.digitize(freqs, edges) - 1
        taper = np.hamming(w)
        use_fd = bool(getattr(self, "f_d_feature", True))  # runs saved before it: True
        f_d = self.physics_.frequency(A[:, :1], segments=segments) if use_fd else None
        rows, ends = [], []
        for a, b in segment_bounds(len(A), segments):
            x = A[a:b, 0]
            if len(x) < w:
                continue
            end = np.arange(w - 1, len(x), hop)
            W = sliding_window_view(x, w)[end - (w - 1)]
            W = np.where(np.isfinite(W), W, 0.0)
            P = np.abs(np.fft.rfft(detrend(W, axis=1) * taper, axis=1)) ** 2
            total = P[:, (band >= 0) & (band < int(self.n_bands))].sum(axis=1) + 1e-30
            bands = np.stack(
                [P[:, band == j].sum(axis=1) for j in range(int(self.n_bands))], axis=1
            )
            feats = [np.log10(bands / total[:, None] + 1e-12)]
            if int(self.n_peaks):
                peaks = np.full((len(P), int(self.n_peaks)), 0.0)
                for i, p in enumerate(P):
                    idx, _ = find_peaks(p)
                    idx = idx[np.argsort(p[idx])[::-1][: int(self.n_peaks)]]
                    peaks[i, : len(idx)] = freqs[idx]
                feats.append(peaks)
            if f_d is not None:
                fd = f_d[a + end]
                feats.append(np.where(np.isfinite(fd), fd, 0.0)[:, None])
            rows.append(np.concatenate(feats, axis=1))
            ends.append(a + end)
        width = int(self.n_bands) + int(self.n_peaks) + int(use_fd)
        if not rows:
            return np.empty((0, width)), np.empty(0, dtype=np.int64)
        return np.concatenate(rows), np.concatenate(ends).astype(np.int64)

    # -- sklearn ------------------------------------------------------------------------
    def fit(
        self, X: ArrayLike, y: ArrayLike, *, segments: ArrayLike | None = None
    ) -> SpectralSpeedRegressor:
        """Fit on recordings ``X`` with true speeds ``y`` (mm/s; NaN samples ignored).

        Raises
        ------
        SlipkitError
            When no full window ends on a sample with a finite speed.
        """
        self._validate_params()
        A = self._check(X)
        yv = np.asarray(y, dtype=np.float64).reshape(-1)
        if len(yv) != len(A):
            raise SlipkitError(
                f"SpectralSpeedRegressor: y has {len(yv)} samples, X {len(A)}"
            )
        with warnings.catch_warnings():
            # The fixed-force warning is about eq. 3's speed scale; here the physics only
            # gives f_d (a feature) and the task's diagnostics, and the speed is learned.
            warnings.simplefilter("ignore", FixedNormalForceWarning)
            self.physics_ = self._physics().fit(A[:, :1], yv, segments=segments)
        F, ends = self.features(A, segments=segments)
        target = yv[ends] if len(ends) else np.empty(0)
        ok = np.isfinite(target) & (target > 0)
        if not ok.any():
            raise SlipkitError(
                "SpectralSpeedRegressor: no full window ends on a sample with a true "
                f"speed (window {int(self.window)} samples); longer pulls are needed"
            )
        reg: Any = (
            HistGradientBoostingRegressor(
                max_iter=int(self.max_iter), random_state=int(self.random_state)
            )
            if self.model == "gbr"
            else make_pipeline(StandardScaler(), Ridge(alpha=float(self.alpha)))
        )
        self.regressor_ = reg.fit(F[ok], target[ok])
        self.n_features_in_ = A.shape[1]
        return self

    def predict(self, X: ArrayLike, *, segments: ArrayLike | None = None) -> FloatArray:
        """Speed per sample (mm/s), held between hops; NaN before a recording's first window."""
        check_is_fitted(self, "regressor_")
        A = self._check(X)
        out = np.full(len(A), np.nan)
        F, ends = self.features(A, segments=segments)
        if not len(ends):
            return out
        v = self.regressor_.predict(F)
        for a, b in segment_bounds(len(A), segments):
            sel = (ends >= a) & (ends < b)
            if not sel.any():
                continue
            e = ends[sel]
            # hold each window's estimate until the next one ends
            idx = np.searchsorted(e, np.arange(a, b), side="right") - 1
            held = np.where(idx >= 0, v[sel][np.maximum(idx, 0)], np.nan)
            out[a:b] = held
        return out

    def __sklearn_tags__(self) -> Any:
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True
        return tags


__all__ = ["SpectralSpeedRegressor"]
