"""The TacTip slip SVM (James, Pestell, Lepora 2018, RA-L 3(4), Sec. III-B2).

A support vector machine on pin-velocity features
(:func:`slipkit.features.velocity_features`), with a Gaussian kernel
``k(x_i, x_j) = exp(-gamma ||x_i - x_j||^2)`` or a linear one. The paper tunes
MATLAB's *kernel scale* KS and *box constraint* BC; here ``gamma = 1 / KS^2``
and ``C = BC`` (Table I: Gaussian (dr, dtheta), KS 38.8, BC 686.6).

The SVM itself is scikit-learn's :class:`~sklearn.svm.SVC` (libsvm); this class
only fixes the paper's choices, optionally standardises the features, and
exposes the fitted kernel scale as a public number for export and reports.
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

# _fit_context and _param_validation are private by name but are the documented way
# for third-party estimators to validate _parameter_constraints (scikit-learn's
# project-template uses them); there is no public alternative in 1.9.
from sklearn.base import BaseEstimator, ClassifierMixin, _fit_context
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_array, check_is_fitted, validate_data

#: The paper's Table I Gaussian (dr, dtheta) hyper-parameters (MATLAB KernelScale
#: and BoxConstraint), tuned by Bayesian optimisation on its own recordings.
PAPER_KERNEL_SCALE = 38.8
PAPER_BOX_CONSTRAINT = 686.6


class TacTipSVM(ClassifierMixin, BaseEstimator):
    """Slip / static classifier of TacTip velocity frames: an SVC with the paper's kernels.

    Parameters
    ----------
    kernel : {"rbf", "linear"}
        Gaussian (``"rbf"``) or linear kernel.
    C : float > 0
        Box constraint (the paper's BC): the penalty on margin violations.
        Default: the paper's 686.6.
    gamma : float > 0 or {"scale", "auto"}
        Gaussian kernel coefficient, 1/(feature unit)^2, applied to the
        standardised features when ``standardize``. Default: the paper's
        ``1 / 38.8^2`` (KS 38.8). ``"scale"`` is
        ``1 / (n_features * X.var())`` and ``"auto"`` is ``1 / n_features``
        (scikit-learn's rules). Ignored by the linear kernel. MATLAB's kernel
        scale is ``KS = 1 / sqrt(gamma)`` (:attr:`kernel_scale`,
        :meth:`from_kernel_scale`).
    standardize : bool
        Scale every feature to zero mean and unit variance (a
        :class:`~sklearn.preprocessing.StandardScaler` in front of the SVC), as
        MATLAB's ``fitcsvm(..., 'Standardize', true)``. Off by default, as in
        MATLAB (so the paper's KS applies to raw features). Raw features weigh
        ``dtheta`` (rad) far above ``dr`` (about 0.01 mm/frame at rest); on the
        simulated gravity drop that still did better (balanced accuracy 0.91
        raw with the paper's KS and BC, 0.71-0.83 standardised).
    class_weight : dict, "balanced" or None
        Per-class multiplier of ``C`` (``"balanced"``: inverse class frequency).
        'slip' frames are rare (4 per trial with ``n_slip=4``).
    features : {"per_pin", "pooled"}
        What the SVC sees. ``"per_pin"``: the rows as given (the paper's one feature
        per pin and kind, tied to the pin count). ``"pooled"``: the rows must be
        per-pin ``dr_dtheta`` features of any pin count, reduced to the six
        pin-count-independent statistics of
        :func:`slipkit.features.pins.pooled_features` (pin speeds, resultant
        length of the directions, mean velocity; missing pins ignored), so a model
        trained on 127 pins scores 331. Use with ``standardize=True``: the
        statistics mix mm/frame and a 0..1 ratio.
    random_state : int, RandomState or None
        Passed to the SVC. The SVC here never draws random numbers (it computes no
        Platt probabilities), so fits are deterministic; the parameter is kept so
        every slipkit estimator takes the same seed from the train config.

    Attributes
    ----------
    classes_ : ndarray of shape (n_classes,)
        Class labels, sorted (``['slip', 'static']`` for TacTip frame labels).
    n_features_in_ : int
        Number of features the SVC sees (with ``features="pooled"``: 6, whatever
        the pin count of ``X``).
    feature_names_in_ : ndarray of str
        Feature names, when ``X`` was a DataFrame with string column names.
    svc_ : SVC
        The fitted SVC (on standardised features when ``standardize``).
    scaler_ : StandardScaler or None
        The fitted scaler, None without standardisation.
    model_ : Pipeline or SVC
        What predicts: ``Pipeline([("scaler", scaler_), ("svc", svc_)])``, or
        ``svc_`` alone. This is the object to export.
    gamma_ : float or None
        The kernel coefficient used (``"scale"`` / ``"auto"`` resolved); None for
        the linear kernel.
    kernel_scale_ : float or None
        ``1 / sqrt(gamma_)``, MATLAB's KernelScale (in standardised units when
        ``standardize``); None for the linear kernel.

    Notes
    -----
    There is no ``predict_proba``: libsvm's Platt scaling fits on internal
    cross-validation folds, so its probabilities can disagree with ``predict``.
    For calibrated probabilities wrap the estimator in
    :class:`~sklearn.calibration.CalibratedClassifierCV` (with a group-aware CV,
    so frames of one trial stay on one side). ``decision_function`` is positive
    for ``classes_[1]`` in the binary case ('static' for TacTip frame labels).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "kernel": [StrOptions({"rbf", "linear"})],
        "C": [Interval(Real, 0.0, None, closed="neither")],
        "gamma": [
            StrOptions({"scale", "auto"}),
            Interval(Real, 0.0, None, closed="neither"),
        ],
        "standardize": ["boolean"],
        "class_weight": [StrOptions({"balanced"}), dict, None],
        "features": [StrOptions({"per_pin", "pooled"})],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        *,
        kernel: str = "rbf",
        C: float = PAPER_BOX_CONSTRAINT,
        gamma: float | str = 1.0 / PAPER_KERNEL_SCALE**2,
        standardize: bool = False,
        class_weight: dict[Any, float] | str | None = None,
        features: str = "per_pin",
        random_state: int | np.random.RandomState | None = None,
    ) -> None:
        self.kernel = kernel
        self.C = C
        self.gamma = gamma
        self.standardize = standardize
        self.class_weight = class_weight
        self.features = features
        self.random_state = random_state

    @property
    def pin_count_independent(self) -> bool:
        """True when any pin count can be scored (``features="pooled"``)."""
        return self.features == "pooled"

    def _pool(self, X: ArrayLike) -> ArrayLike:
        if self.features != "pooled":
            return X
        # Pooled statistics of any pin count: the width check is pooled_features's.
        from slipkit.features.pins import pooled_features

        return pooled_features(check_array(X, dtype=np.float64))

    @classmethod
    def from_kernel_scale(cls, kernel_scale: float, **params: Any) -> TacTipSVM:
        """A Gaussian SVM from MATLAB's KernelScale (``gamma = 1 / KS^2``).

        ``TacTipSVM.from_kernel_scale(38.8, C=686.6)`` is the paper's Table I
        Gaussian (dr, dtheta) setting, which is also the default.
        """
        if not (math.isfinite(kernel_scale) and kernel_scale > 0):
            raise ValueError(
                f"kernel_scale must be a finite number > 0; got {kernel_scale!r}"
            )
        return cls(gamma=1.0 / kernel_scale**2, **params)

    @property
    def kernel_scale(self) -> float:
        """MATLAB's KernelScale of the ``gamma`` parameter, ``1 / sqrt(gamma)`` (read-only).

        Raises AttributeError for ``gamma="scale"`` or ``"auto"``, which depend on
        the data: read ``kernel_scale_`` after ``fit``.
        """
        if isinstance(self.gamma, str):
            raise AttributeError(
                f"gamma={self.gamma!r} is resolved from the data in fit; read kernel_scale_ after fitting"
            )
        return 1.0 / math.sqrt(float(self.gamma))

    def _resolve_gamma(self, X: NDArray[np.float64]) -> float | None:
        # Resolved here rather than read back from SVC's private ``_gamma``, so the
        # kernel scale is a public fitted attribute; same rule as SVC's fit.
        if self.kernel == "linear":
            return None
        if self.gamma == "scale":
            var = float(X.var())
            return 1.0 / (X.shape[1] * var) if var != 0 else 1.0
        if self.gamma == "auto":
            return 1.0 / X.shape[1]
        return float(self.gamma)

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(
        self, X: ArrayLike, y: ArrayLike, sample_weight: ArrayLike | None = None
    ) -> TacTipSVM:
        """Fit the scaler (if any) and the SVC.

        Parameters
        ----------
        X : array_like of shape (n_frames, n_features)
            Velocity-frame features (mm/frame and rad).
        y : array_like of shape (n_frames,)
            Frame labels ('slip' / 'static'); at least two classes.
        sample_weight : array_like of shape (n_frames,), optional
            Per-frame weights (scale ``C`` per sample, and weight the scaler).

        Returns
        -------
        TacTipSVM
            self, fitted.
        """
        X, y = validate_data(self, self._pool(X), y, dtype=np.float64, order="C")
        Xt: NDArray[np.float64] = np.asarray(X)
        self.scaler_: StandardScaler | None = None
        if self.standardize:
            self.scaler_ = StandardScaler().fit(Xt, sample_weight=sample_weight)
            Xt = np.asarray(self.scaler_.transform(Xt))
        self.gamma_ = self._resolve_gamma(Xt)
        self.kernel_scale_ = (
            None if self.gamma_ is None else 1.0 / math.sqrt(self.gamma_)
        )
        self.svc_ = SVC(
            kernel=self.kernel,
            C=self.C,
            gamma="scale" if self.gamma_ is None else self.gamma_,
            class_weight=self.class_weight,
            random_state=self.random_state,
        ).fit(Xt, y, sample_weight=sample_weight)
        self.classes_ = self.svc_.classes_
        self.model_: Pipeline | SVC = (
            self.svc_
            if self.scaler_ is None
            else Pipeline([("scaler", self.scaler_), ("svc", self.svc_)])
        )
        return self

    def _features(self, X: ArrayLike) -> NDArray[np.float64]:
        check_is_fitted(self)
        # reset=False: keep n_features_in_ from fit, only check the shape and names.
        return np.asarray(
            validate_data(self, self._pool(X), reset=False, dtype=np.float64, order="C")
        )

    def decision_function(self, X: ArrayLike) -> NDArray[np.float64]:
        """Signed distance to the separating surface (positive: ``classes_[1]``).

        Parameters
        ----------
        X : array_like of shape (n_frames, n_features)

        Returns
        -------
        ndarray of shape (n_frames,) or (n_frames, n_classes)
            One score per frame for two classes, one per class (one-vs-rest shape)
            for more.
        """
        Xt = self._features(X)  # checks fitted before model_ is read
        return np.asarray(self.model_.decision_function(Xt))

    def predict(self, X: ArrayLike) -> NDArray[Any]:
        """Class label of every frame.

        Parameters
        ----------
        X : array_like of shape (n_frames, n_features)

        Returns
        -------
        ndarray of shape (n_frames,)
            Labels from ``classes_``.
        """
        Xt = self._features(X)  # checks fitted before model_ is read
        return np.asarray(self.model_.predict(Xt))
