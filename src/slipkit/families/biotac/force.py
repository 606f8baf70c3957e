"""BioTac force regression (Su et al. 2015, Humanoids, Sec. IV-A and V-A).

Three scikit-learn regressors map electrode frames ``(n_frames, n_electrodes)`` (ADC
counts, optionally followed by extra columns such as the DC pressure) to the force the
fingertip applies, ``(Fx, Fy, Fz)`` in N:

- :class:`WeightedNormalsRegressor`: the analytic baseline
  ``F_k = S_k sum_i E_i N_k,i + o_k`` with the electrode normals ``N_i`` of
  :mod:`slipkit.families.biotac.physics` and three scales ``S`` (N/count) fitted by linear
  regression; the offsets ``o`` absorb the unloaded baseline.
- :class:`ForceMLP`: a torch multi-layer perceptron trained through skorch with early
  stopping on a validation set; ``hidden=(38,)`` is the 1-layer network of Su et al.
  (after Wettels et al.), ``hidden=(10, 10, 10)`` the paper's 3-layer model.
- :class:`LocalLinearRegressor`: locally weighted linear regression in the spirit of
  LWPR (Vijayakumar et al.), with receptive fields from k-means.

All three accept a 1-D ``y`` as well (one output), so scikit-learn's estimator checks
apply to them.
"""

from __future__ import annotations

from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

# _fit_context and _param_validation are private by name but are the documented way
# for third-party estimators to validate _parameter_constraints (see models/svm.py).
from sklearn.base import BaseEstimator, RegressorMixin, _fit_context
from sklearn.cluster import KMeans
from sklearn.linear_model import LinearRegression, Ridge
from sklearn.preprocessing import StandardScaler
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted, validate_data

from slipkit.families.biotac.physics import ELECTRODE_NORMALS

__all__ = ["ForceMLP", "LocalLinearRegressor", "WeightedNormalsRegressor"]

FloatArray = NDArray[np.float64]


def _as_2d_target(y: ArrayLike) -> tuple[FloatArray, bool]:
    """``y`` as (n, n_outputs) float64, and whether it came in 1-D."""
    arr = np.asarray(y, dtype=np.float64)
    return (arr.reshape(-1, 1), True) if arr.ndim == 1 else (arr, False)


def _shape_prediction(pred: FloatArray, one_d: bool) -> FloatArray:
    return pred.ravel() if one_d else pred


class WeightedNormalsRegressor(RegressorMixin, BaseEstimator):
    """The analytic weighted-normals force estimate (Su et al. 2015, Sec. IV-A).

    ``F_k = S_k w_k + o_k`` with ``w_k = sum_i E_i N_k,i`` the electrode values
    weighted by the ``k``-th component of each electrode's unit normal. One
    :class:`~sklearn.linear_model.LinearRegression` per axis fits ``S_k`` and ``o_k``
    on ``w_k`` alone: the paper's three scales, no cross-axis terms.

    Baseline: ``E_i`` is an impedance *change*. Passing raw counts ``c_i = E_i + b_i``
    gives ``w_k = sum E_i N_k,i + sum b_i N_k,i``; the second sum is a constant per
    axis, so the fitted offset ``o_k`` absorbs any constant unloaded baseline
    (``o_k = -S_k sum_i b_i N_k,i``). With electrodes already relative to the
    no-contact frame (what ``ForceRegression(baseline="first")`` passes), ``o_k`` is
    near zero and soaks up what remains (drift, the average of the non-linear
    residual). ``fit_intercept=False`` is the paper's bare form.

    Parameters
    ----------
    normals : array-like of shape (n_electrodes, n_axes) or None
        Electrode unit normals; None: the 19 BioTac normals of
        :data:`slipkit.families.biotac.physics.ELECTRODE_NORMALS` (3 axes). The first
        ``n_electrodes`` columns of ``X`` are the electrodes; further columns (e.g.
        the DC pressure) are ignored by this model.
    fit_intercept : bool
        Fit the per-axis offsets ``o_k`` (N).

    Attributes
    ----------
    scales_ : ndarray of shape (n_axes,)
        ``S_k`` (N per count).
    offsets_ : ndarray of shape (n_axes,)
        ``o_k`` (N); zeros when ``fit_intercept=False``.
    regressors_ : list of LinearRegression
        The per-axis fits on ``w_k``.
    normals_ : ndarray of shape (n_electrodes, n_axes)
        The normals used.
    n_features_in_ : int
        Columns of ``X`` seen in ``fit`` (>= ``n_electrodes``).
    n_outputs_ : int
        Number of force axes (``n_axes``).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "normals": ["array-like", None],
        "fit_intercept": ["boolean"],
    }

    def __init__(
        self, *, normals: ArrayLike | None = None, fit_intercept: bool = True
    ) -> None:
        self.normals = normals
        self.fit_intercept = fit_intercept

    def _normals(self) -> FloatArray:
        n = np.asarray(
            ELECTRODE_NORMALS if self.normals is None else self.normals,
            dtype=np.float64,
        )
        if n.ndim != 2 or n.shape[0] < 1 or n.shape[1] < 1 or not np.isfinite(n).all():
            raise ValueError(
                f"normals must be a finite (n_electrodes, n_axes) matrix; got shape {n.shape}"
            )
        return n

    def __sklearn_tags__(self) -> Any:
        tags = super().__sklearn_tags__()
        try:
            n_axes = self._normals().shape[1]
        except ValueError:  # bad normals are reported by fit, not by a tag lookup
            n_axes = 3
        tags.target_tags.single_output = n_axes == 1
        tags.target_tags.multi_output = n_axes > 1
        # A three-parameter physical model, not a general regressor.
        tags.regressor_tags.poor_score = True
        return tags

    def _weighted(self, X: FloatArray, normals: FloatArray) -> FloatArray:
        if X.shape[1] < normals.shape[0]:
            raise ValueError(
                f"X has n_features = {X.shape[1]}; the weighted-normals model needs "
                f"its {normals.shape[0]} electrode columns first"
            )
        return X[:, : normals.shape[0]] @ normals

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X: ArrayLike, y: ArrayLike) -> WeightedNormalsRegressor:
        """Fit the scales (and offsets) axis by axis.

        Parameters
        ----------
        X : array-like of shape (n_frames, n_features)
            Electrode values (counts), electrodes first.
        y : array-like of shape (n_frames, n_axes) or (n_frames,)
            Force (N); 1-D only when the normals have one axis.

        Returns
        -------
        WeightedNormalsRegressor
            self, fitted.
        """
        normals = self._normals()
        # One axis: y is a single output (a column vector is raveled with sklearn's
        # DataConversionWarning); several axes: y must have one column per axis.
        X, y = validate_data(
            self,
            X,
            y,
            multi_output=normals.shape[1] > 1,
            y_numeric=True,
            dtype=np.float64,
        )
        Y, self._y_1d = _as_2d_target(y)
        if Y.shape[1] != normals.shape[1]:
            raise ValueError(
                f"y has {Y.shape[1]} outputs but the normals have {normals.shape[1]} "
                "axes (one scale per axis)"
            )
        w = self._weighted(np.asarray(X), normals)
        self.regressors_ = [
            LinearRegression(fit_intercept=self.fit_intercept).fit(w[:, [k]], Y[:, k])
            for k in range(Y.shape[1])
        ]
        self.scales_ = np.array([float(r.coef_[0]) for r in self.regressors_])
        self.offsets_ = np.array([float(r.intercept_) for r in self.regressors_])
        self.normals_ = normals
        self.n_outputs_ = Y.shape[1]
        return self

    def predict(self, X: ArrayLike) -> FloatArray:
        """Force (N) of every frame.

        Parameters
        ----------
        X : array-like of shape (n_frames, n_features)

        Returns
        -------
        ndarray of shape (n_frames, n_axes), or (n_frames,) for a 1-D ``y`` in fit
        """
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=np.float64)
        pred = self._weighted(np.asarray(X), self.normals_) * self.scales_
        return _shape_prediction(pred + self.offsets_, self._y_1d)


# -- torch MLP through skorch ---------------------------------------------------------

_ACTIVATIONS = ("tanh", "relu", "sigmoid", "identity")


def _mlp_module(n_in: int, hidden: Sequence[int], n_out: int, activation: str) -> Any:
    """A torch ``Sequential`` MLP: Linear -> activation per hidden layer -> Linear."""
    from torch import nn

    act = {
        "tanh": nn.Tanh,
        "relu": nn.ReLU,
        "sigmoid": nn.Sigmoid,
        "identity": nn.Identity,
    }[activation]
    layers: list[Any] = []
    width = n_in
    for h in hidden:
        layers += [nn.Linear(width, int(h)), act()]
        width = int(h)
    layers.append(nn.Linear(width, n_out))
    return nn.Sequential(*layers)


class ForceMLP(RegressorMixin, BaseEstimator):
    """Electrode frames -> force with a torch MLP trained by skorch (Su et al. 2015).

    Inputs and targets are standardised (:class:`~sklearn.preprocessing.StandardScaler`
    each); the network sees float32. ``hidden=(38,)`` with tanh is the 1-layer
    network (twice the 19 inputs), ``hidden=(10, 10, 10)`` the paper's 3-layer model;
    the output layer is linear. The paper trained with Levenberg-Marquardt (MATLAB);
    here Adam on the mean squared error with mini-batches, stopped early when the
    validation loss has not improved for ``patience`` epochs, and the best epoch's
    weights restored (``EarlyStopping(load_best=True)``).

    Validation set: ``fit(X, y, validation_data=(X_val, y_val))`` uses the caller's
    (``ForceRegression`` passes its held-out 30 s blocks). Without it the last
    ``validation_fraction`` of the rows, in their given order, is held out: a
    contiguous tail, so that neighbouring, near-identical frames do not fall on both
    sides as a random row split would put them.

    Parameters
    ----------
    hidden : sequence of int
        Units per hidden layer.
    activation : {"tanh", "relu", "sigmoid", "identity"}
        Hidden-layer activation.
    max_epochs : int
        Upper bound on training epochs.
    lr : float
        Adam learning rate (in standardised units).
    batch_size : int
        Frames per mini-batch.
    patience : int
        Epochs without validation improvement before stopping.
    validation_fraction : float in [0, 1)
        Tail fraction held out when no ``validation_data`` is given; 0: no early
        stopping (all ``max_epochs`` run).
    weight_decay : float
        Adam L2 penalty.
    n_threads : int
        Torch intra-op threads while fitting and predicting (restored afterwards).
    random_state : int, RandomState or None
        Seeds the weight initialisation and the batch shuffling (torch's RNG is
        forked, so the global torch state is left untouched).

    Attributes
    ----------
    net_ : skorch.NeuralNetRegressor
        The fitted skorch net (on standardised inputs and targets).
    module_ : torch.nn.Sequential
        The fitted torch module (for ONNX export): standardised float32 in,
        standardised force out.
    x_scaler_, y_scaler_ : StandardScaler
        Input and target standardisation; ``F = y_scaler_.inverse_transform(module_(
        x_scaler_.transform(X)))``.
    n_epochs_ : int
        Epochs run.
    best_epoch_ : int
        Epoch (1-based) whose weights were kept.
    best_valid_loss_ : float or None
        Validation MSE (standardised units) of that epoch; None without validation.
    n_features_in_ : int
        Input columns.
    n_outputs_ : int
        Output columns.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "hidden": ["array-like"],
        "activation": [StrOptions(set(_ACTIVATIONS))],
        "max_epochs": [Interval(Integral, 1, None, closed="left")],
        "lr": [Interval(Real, 0.0, None, closed="neither")],
        "batch_size": [Interval(Integral, 1, None, closed="left")],
        "patience": [Interval(Integral, 1, None, closed="left")],
        "validation_fraction": [Interval(Real, 0.0, 1.0, closed="left")],
        "weight_decay": [Interval(Real, 0.0, None, closed="left")],
        "n_threads": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        *,
        hidden: Sequence[int] = (10, 10, 10),
        activation: str = "tanh",
        max_epochs: int = 200,
        lr: float = 3e-3,
        batch_size: int = 256,
        patience: int = 10,
        validation_fraction: float = 0.2,
        weight_decay: float = 0.0,
        n_threads: int = 1,
        random_state: int | np.random.RandomState | None = None,
    ) -> None:
        self.hidden = hidden
        self.activation = activation
        self.max_epochs = max_epochs
        self.lr = lr
        self.batch_size = batch_size
        self.patience = patience
        self.validation_fraction = validation_fraction
        self.weight_decay = weight_decay
        self.n_threads = n_threads
        self.random_state = random_state

    def __sklearn_tags__(self) -> Any:
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags

    def _hidden(self) -> tuple[int, ...]:
        hidden = tuple(int(h) for h in np.atleast_1d(np.asarray(self.hidden)))
        if any(h < 1 for h in hidden):
            raise ValueError(f"hidden units must be >= 1; got {self.hidden!r}")
        return hidden

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(
        self,
        X: ArrayLike,
        y: ArrayLike,
        validation_data: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> ForceMLP:
        """Standardise, then train the network with early stopping.

        Parameters
        ----------
        X : array-like of shape (n_frames, n_features)
            Electrode values (counts) and any extra columns.
        y : array-like of shape (n_frames, n_outputs) or (n_frames,)
            Force (N).
        validation_data : (X_val, y_val), optional
            The early-stopping set; default: the tail ``validation_fraction`` of
            ``X``.

        Returns
        -------
        ForceMLP
            self, fitted.
        """
        import torch
        from skorch import NeuralNetRegressor
        from skorch.callbacks import EarlyStopping
        from skorch.dataset import Dataset as SkorchDataset
        from skorch.helper import predefined_split

        X, y = validate_data(
            self, X, y, multi_output=True, y_numeric=True, dtype=np.float64
        )
        Y, self._y_1d = _as_2d_target(y)
        Xa = np.asarray(X)
        if validation_data is not None:
            Xv = np.asarray(
                validate_data(self, validation_data[0], reset=False, dtype=np.float64)
            )
            Yv = _as_2d_target(np.asarray(validation_data[1]))[0]
            if Yv.shape[1] != Y.shape[1] or len(Yv) != len(Xv):
                raise ValueError(
                    f"validation_data has {len(Xv)} rows and {Yv.shape[1]} outputs; "
                    f"expected as many rows as X_val and {Y.shape[1]} outputs"
                )
            Xt, Yt = Xa, Y
        else:
            n_val = int(np.floor(self.validation_fraction * len(Xa)))
            if n_val >= len(Xa):
                n_val = 0
            cut = len(Xa) - n_val
            Xt, Yt, Xv, Yv = Xa[:cut], Y[:cut], Xa[cut:], Y[cut:]
        self.x_scaler_ = StandardScaler().fit(Xt)
        self.y_scaler_ = StandardScaler().fit(Yt)
        xs = self.x_scaler_.transform(Xt).astype(np.float32)
        ys = self.y_scaler_.transform(Yt).astype(np.float32)
        has_val = len(Xv) > 0
        callbacks: list[Any] = []
        train_split: Any = None
        if has_val:
            valid = SkorchDataset(
                self.x_scaler_.transform(Xv).astype(np.float32),
                self.y_scaler_.transform(Yv).astype(np.float32),
            )
            train_split = predefined_split(valid)
            callbacks.append(
                EarlyStopping(
                    monitor="valid_loss",
                    patience=self.patience,
                    threshold=1e-4,
                    load_best=True,
                )
            )
        seed = int(check_random_state(self.random_state).randint(2**31 - 1))
        threads = torch.get_num_threads()
        try:
            torch.set_num_threads(self.n_threads)
            # fork_rng: seed the init and shuffling without touching global torch state.
            with torch.random.fork_rng(devices=[]):
                torch.manual_seed(seed)
                self.net_ = NeuralNetRegressor(
                    module=_mlp_module(
                        xs.shape[1], self._hidden(), ys.shape[1], self.activation
                    ),
                    max_epochs=self.max_epochs,
                    lr=self.lr,
                    batch_size=self.batch_size,
                    optimizer=torch.optim.Adam,
                    optimizer__weight_decay=self.weight_decay,
                    iterator_train__shuffle=True,
                    train_split=train_split,
                    callbacks=callbacks,
                    device="cpu",
                    verbose=0,
                )
                self.net_.fit(xs, ys)
        finally:
            torch.set_num_threads(threads)
        self.module_ = self.net_.module_
        history = self.net_.history
        self.n_epochs_ = len(history)
        if has_val:
            losses = np.asarray(history[:, "valid_loss"], dtype=np.float64)
            best = int(np.argmin(losses))
            self.best_epoch_ = best + 1
            self.best_valid_loss_: float | None = float(losses[best])
        else:
            self.best_epoch_ = self.n_epochs_
            self.best_valid_loss_ = None
        self.n_outputs_ = Y.shape[1]
        return self

    def predict(self, X: ArrayLike) -> FloatArray:
        """Force (N) of every frame.

        Parameters
        ----------
        X : array-like of shape (n_frames, n_features)

        Returns
        -------
        ndarray of shape (n_frames, n_outputs), or (n_frames,) for a 1-D ``y`` in fit
        """
        import torch

        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=np.float64)
        xs = self.x_scaler_.transform(np.asarray(X)).astype(np.float32)
        threads = torch.get_num_threads()
        try:
            torch.set_num_threads(self.n_threads)
            # torch's DataLoader draws a base seed even without shuffling: fork so
            # that predicting leaves the global torch RNG alone.
            with torch.random.fork_rng(devices=[]):
                out = np.asarray(self.net_.predict(xs), dtype=np.float64)
        finally:
            torch.set_num_threads(threads)
        pred = self.y_scaler_.inverse_transform(out.reshape(len(xs), -1))
        return _shape_prediction(np.asarray(pred, dtype=np.float64), self._y_1d)


# -- locally weighted linear regression -----------------------------------------------


class LocalLinearRegressor(RegressorMixin, BaseEstimator):
    """Locally weighted linear regression in the spirit of LWPR (Su et al. 2015, Sec. IV-A).

    LWPR (Vijayakumar, D'Souza, Schaal 2005) predicts ``sum_k w_k psi_k(x) / sum_k
    w_k`` from local linear models ``psi_k`` whose Gaussian receptive fields ``w_k``
    are placed, sized and fitted incrementally (with partial least squares inside
    each field). No maintained LWPR package exists for current Python, and the
    incremental machinery matters for online learning, not for a batch comparison,
    so this is a batch analogue built from scikit-learn parts:

    1. inputs standardised (:class:`~sklearn.preprocessing.StandardScaler`);
    2. ``n_fields`` receptive-field centres ``c_k`` from
       :class:`~sklearn.cluster.KMeans` (seeded);
    3. Gaussian activations ``a_k(x) = exp(-||x - c_k||^2 / (2 h^2))``, one
       bandwidth ``h`` for all fields (``bandwidth`` x the median distance from a
       centre to its nearest other centre, so neighbouring fields overlap);
    4. one :class:`~sklearn.linear_model.Ridge` per field on ``x - c_k``, each row
       weighted by its normalised activation ``a_k / sum_j a_j`` (normalised so every
       frame counts once in total and far-away frames cannot make a field's fit
       singular; ridge instead of PLS for the same reason);
    5. prediction: the normalised mix ``sum_k a_k psi_k(x) / sum_k a_k`` (computed as
       a softmax of ``-d^2 / 2 h^2``, so it never divides by zero far from all
       centres).

    Parameters
    ----------
    n_fields : int
        Receptive fields (capped at the number of distinct training rows).
    bandwidth : float
        Gaussian width ``h`` as a multiple of the median nearest-centre distance.
    alpha : float
        Ridge penalty of each local model (standardised units).
    random_state : int, RandomState or None
        Seeds k-means.

    Attributes
    ----------
    scaler_ : StandardScaler
        Input standardisation.
    centres_ : ndarray of shape (n_fields_, n_features)
        Field centres (standardised units).
    width_ : float
        ``h`` (standardised units).
    local_models_ : list of Ridge
        One per field, on ``x - c_k``.
    n_fields_ : int
        Fields used.
    n_features_in_ : int
        Input columns.
    n_outputs_ : int
        Output columns.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "n_fields": [Interval(Integral, 1, None, closed="left")],
        "bandwidth": [Interval(Real, 0.0, None, closed="neither")],
        "alpha": [Interval(Real, 0.0, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        *,
        n_fields: int = 30,
        bandwidth: float = 1.0,
        alpha: float = 1e-3,
        random_state: int | np.random.RandomState | None = None,
    ) -> None:
        self.n_fields = n_fields
        self.bandwidth = bandwidth
        self.alpha = alpha
        self.random_state = random_state

    def __sklearn_tags__(self) -> Any:
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags

    def _activations(self, xs: FloatArray) -> FloatArray:
        """Normalised activations (n, n_fields_): a softmax of ``-d^2 / 2 h^2``."""
        from scipy.special import softmax
        from sklearn.metrics.pairwise import euclidean_distances

        # (n, n_fields) without an (n, n_fields, n_features) temporary.
        d2 = euclidean_distances(xs, self.centres_, squared=True)
        return np.asarray(softmax(-d2 / (2.0 * self.width_**2), axis=1))

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X: ArrayLike, y: ArrayLike) -> LocalLinearRegressor:
        """Place the fields and fit one weighted ridge regression per field.

        Parameters
        ----------
        X : array-like of shape (n_frames, n_features)
        y : array-like of shape (n_frames, n_outputs) or (n_frames,)
            Force (N).

        Returns
        -------
        LocalLinearRegressor
            self, fitted.
        """
        X, y = validate_data(
            self, X, y, multi_output=True, y_numeric=True, dtype=np.float64
        )
        Y, self._y_1d = _as_2d_target(y)
        self.scaler_ = StandardScaler().fit(X)
        xs = np.asarray(self.scaler_.transform(X))
        n_distinct = len(np.unique(xs, axis=0))
        self.n_fields_ = int(min(self.n_fields, n_distinct))
        km = KMeans(
            n_clusters=self.n_fields_, n_init=3, random_state=self.random_state
        ).fit(xs)
        self.centres_ = np.asarray(km.cluster_centers_, dtype=np.float64)
        if self.n_fields_ > 1:
            dc = np.sqrt(
                ((self.centres_[:, None, :] - self.centres_[None, :, :]) ** 2).sum(-1)
            )
            np.fill_diagonal(dc, np.inf)
            spacing = float(np.median(dc.min(axis=1)))
        else:
            spacing = float(np.sqrt(xs.var(axis=0).sum()))
        self.width_ = self.bandwidth * (spacing if spacing > 0 else 1.0)
        act = self._activations(xs)
        self.local_models_ = [
            Ridge(alpha=self.alpha).fit(xs - c, Y, sample_weight=act[:, k])
            for k, c in enumerate(self.centres_)
        ]
        self.n_outputs_ = Y.shape[1]
        return self

    def predict(self, X: ArrayLike) -> FloatArray:
        """Force (N): the activation-weighted mix of the local linear models.

        Parameters
        ----------
        X : array-like of shape (n_frames, n_features)

        Returns
        -------
        ndarray of shape (n_frames, n_outputs), or (n_frames,) for a 1-D ``y`` in fit
        """
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=np.float64)
        xs = np.asarray(self.scaler_.transform(X))
        act = self._activations(xs)
        pred = np.zeros((len(xs), self.n_outputs_))
        for k, (c, m) in enumerate(zip(self.centres_, self.local_models_, strict=True)):
            pred += act[:, [k]] * np.asarray(m.predict(xs - c)).reshape(len(xs), -1)
        return _shape_prediction(pred, self._y_1d)
