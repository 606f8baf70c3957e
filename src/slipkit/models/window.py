"""Window classifiers of slip type: the paper's MLP and a small 1-D CNN, on skorch.

Su et al. 2015 (Sec. IV-C) classify linear versus rotational slip from a window of
100 consecutive frames of the 19 BioTac electrodes, flattened to 1900 inputs, with
"one hidden layer with 50 neurons [...] a sigmoid transfer function [and] softmax
[...] in the output neurons" (:class:`WindowMLP`). :class:`WindowCNN` reads the same
flattened window as ``W`` frames of ``C`` electrodes and convolves over time, to show
what a temporal model buys and costs (``n_parameters_``, ``flops_per_window_``);
:class:`WindowGRU` steps a GRU through the window frame by frame.

Both are scikit-learn classifiers around :class:`skorch.NeuralNetClassifier`, which
gives the training loop, early stopping on a validation split and the estimator API
(nothing hand-written there). The paper trained with a 20 % validation split for early
stopping; here that split is by ``groups`` when given (the windows of one trial overlap,
so a random split of windows would let validation see training frames).
"""

from __future__ import annotations

from abc import abstractmethod
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

# _fit_context and _param_validation are private by name but are the documented way
# for third-party estimators to validate _parameter_constraints (scikit-learn's
# project-template uses them); there is no public alternative in 1.9.
from sklearn.base import BaseEstimator, ClassifierMixin, _fit_context
from sklearn.model_selection import GroupShuffleSplit, StratifiedShuffleSplit
from sklearn.preprocessing import LabelEncoder, StandardScaler
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data
from skorch import NeuralNetClassifier
from skorch.callbacks import EarlyStopping
from skorch.dataset import Dataset as SkorchDataset
from skorch.helper import predefined_split
from torch import nn
from torch.utils.flop_counter import FlopCounterMode

__all__ = [
    "GRUModule",
    "MLPModule",
    "TemporalCNNModule",
    "WindowCNN",
    "WindowGRU",
    "WindowMLP",
]

_ACTIVATIONS: dict[str, type[nn.Module]] = {
    "sigmoid": nn.Sigmoid,
    "tanh": nn.Tanh,
    "relu": nn.ReLU,
}


class MLPModule(nn.Module):
    """Flattened window -> one hidden layer -> class probabilities (softmax).

    Parameters
    ----------
    n_features, hidden_units, n_classes : int
        Input length (W x C), hidden units (paper: 50), classes.
    activation : {"sigmoid", "tanh", "relu"}
        Hidden transfer function (paper: sigmoid).
    """

    def __init__(
        self,
        n_features: int,
        hidden_units: int,
        n_classes: int,
        activation: str = "sigmoid",
    ) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(n_features, hidden_units),
            _ACTIVATIONS[activation](),
            nn.Linear(hidden_units, n_classes),
            nn.Softmax(dim=-1),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class TemporalCNNModule(nn.Module):
    """Flattened window -> (C, W) -> 1-D convolutions over time -> mean over time -> softmax.

    Electrodes are the input channels. Padding keeps the length, so any ``W >= 1``
    works, and every shape is static (a 1-D CNN exports to ONNX with a free batch
    size, unlike a GRU under torch 2.13's dynamo exporter).

    Parameters
    ----------
    n_channels, width, n_classes : int
        Electrodes C, frames per window W, classes.
    filters, kernel_size, n_layers : int
        Convolution channels, kernel length in frames (odd), convolution layers.
    """

    def __init__(
        self,
        n_channels: int,
        width: int,
        n_classes: int,
        filters: int = 16,
        kernel_size: int = 5,
        n_layers: int = 2,
    ) -> None:
        super().__init__()
        self.n_channels = n_channels
        self.width = width
        layers: list[nn.Module] = []
        c_in = n_channels
        for _ in range(n_layers):
            layers += [
                nn.Conv1d(c_in, filters, kernel_size, padding=kernel_size // 2),
                nn.ReLU(),
            ]
            c_in = filters
        self.conv = nn.Sequential(*layers)
        self.head = nn.Sequential(nn.Linear(filters, n_classes), nn.Softmax(dim=-1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # (N, W*C) time-major -> (N, W, C) -> (N, C, W): electrodes as channels.
        z = x.reshape(-1, self.width, self.n_channels).transpose(1, 2)
        return self.head(self.conv(z).mean(dim=-1))


class GRUModule(nn.Module):
    """Flattened window -> (W, C) -> a GRU stepping frame by frame -> last state -> softmax.

    Each window starts from a zero hidden state: no state is carried from one
    window (or one call of the runtime) to the next, so the exported graph is
    "whole window in, class out" like the other window models.

    Parameters
    ----------
    n_channels, width, n_classes : int
        Electrodes C, frames per window W, classes.
    hidden_units, n_layers : int
        GRU state size and stacked layers.
    """

    def __init__(
        self,
        n_channels: int,
        width: int,
        n_classes: int,
        hidden_units: int = 32,
        n_layers: int = 1,
    ) -> None:
        super().__init__()
        self.n_channels = n_channels
        self.width = width
        self.hidden_units = hidden_units
        self.n_layers = n_layers
        self.n_classes = n_classes
        self.gru = nn.GRU(n_channels, hidden_units, n_layers, batch_first=True)
        self.head = nn.Sequential(
            nn.Linear(hidden_units, n_classes), nn.Softmax(dim=-1)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # (N, W*C) time-major -> (N, W, C): one GRU step per frame.
        out, _ = self.gru(x.reshape(-1, self.width, self.n_channels))
        return self.head(out[:, -1])

    def flops_per_window(self) -> int:
        """Multiply-adds (x 2) of the GRU gates over W frames and of the head.

        torch's FLOP counter does not count the fused GRU kernel, so this is the
        closed form: per frame and layer, three gates of ``in x h + h x h`` weights.
        """
        h = self.hidden_units
        per_step = 0
        c_in = self.n_channels
        for _ in range(self.n_layers):
            per_step += 2 * 3 * (c_in * h + h * h)
            c_in = h
        return int(self.width * per_step + 2 * h * self.n_classes)


class _WindowNet(ClassifierMixin, BaseEstimator):
    """Shared fit/predict of the window classifiers (subclasses build the module)."""

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "lr": [Interval(Real, 0.0, None, closed="neither")],
        "weight_decay": [Interval(Real, 0.0, None, closed="left")],
        "max_epochs": [Interval(Integral, 1, None, closed="left")],
        "batch_size": [Interval(Integral, 1, None, closed="left")],
        "patience": [Interval(Integral, 1, None, closed="left")],
        "validation_fraction": [Interval(Real, 0.0, 1.0, closed="left")],
        "standardize": ["boolean"],
        "num_threads": [Interval(Integral, 1, None, closed="left"), None],
        "random_state": ["random_state"],
    }

    # Set by subclasses' __init__ (declared for mypy).
    lr: float
    weight_decay: float
    max_epochs: int
    batch_size: int
    patience: int
    validation_fraction: float
    standardize: bool
    num_threads: int | None
    random_state: int | None

    @abstractmethod
    def _module(
        self, n_features: int, n_classes: int
    ) -> tuple[type[nn.Module], dict[str, Any]]:
        """The module class and its keyword arguments for this input and class count."""

    def _frames(self, n_features: int) -> int:
        """Frames per window of a temporal model (``n_channels`` values each), set as
        ``width_``; an input that is not whole frames is refused naming the fix."""
        n_channels = int(getattr(self, "n_channels", 1))
        if n_features % n_channels:
            raise ValueError(
                f"{type(self).__name__}: {n_features} inputs per window is not a "
                f"multiple of n_channels={n_channels}; set n_channels to the "
                "stream's channel count"
            )
        self.width_ = n_features // n_channels
        return self.width_

    def _seed(self) -> int:
        # An int seed keeps fits repeatable; None draws one (scikit-learn's meaning).
        rs = self.random_state
        if rs is None:
            return int(np.random.default_rng().integers(2**31))
        if isinstance(rs, np.random.RandomState):
            return int(rs.randint(2**31))
        return int(rs)

    def _valid_split(
        self, y: NDArray[np.int64], groups: ArrayLike | None, seed: int
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]] | None:
        """Train and validation rows, or None when there is too little data to hold any out."""
        n = len(y)
        frac = self.validation_fraction
        counts = np.bincount(y)
        if frac == 0 or n * frac < len(counts) or counts.min() < 2:
            return None
        rows = np.arange(n)
        if groups is not None:
            g = np.asarray(groups)
            if len(np.unique(g)) < 2:
                return None
            tr, va = next(
                GroupShuffleSplit(1, test_size=frac, random_state=seed).split(
                    rows, groups=g
                )
            )
        else:
            tr, va = next(
                StratifiedShuffleSplit(1, test_size=frac, random_state=seed).split(
                    rows, y
                )
            )
        return tr, va

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(
        self, X: ArrayLike, y: ArrayLike, *, groups: ArrayLike | None = None
    ) -> _WindowNet:
        """Standardise, split off validation rows, train with early stopping.

        Parameters
        ----------
        X : array_like of shape (n_windows, width * n_channels)
            Flattened windows (:func:`slipkit.features.windows.sliding_windows`).
        y : array_like of shape (n_windows,)
            Class of each window (e.g. 'linear' / 'rotational').
        groups : array_like of shape (n_windows,), optional
            Group of each window (its trial, or its object under a by-object
            split): the validation rows are whole groups, so overlapping windows
            of one trial never sit on both sides.

        Returns
        -------
        self
        """
        X, y = validate_data(self, X, y, dtype=np.float32, order="C")
        check_classification_targets(y)
        encoder = LabelEncoder().fit(y)
        self.classes_ = encoder.classes_
        yi = encoder.transform(y).astype(np.int64)
        Xt = np.asarray(X, dtype=np.float32)
        self.scaler_: StandardScaler | None = None
        if self.standardize:
            self.scaler_ = StandardScaler().fit(Xt)
            Xt = np.asarray(self.scaler_.transform(Xt), dtype=np.float32)
        seed = self._seed()
        split = self._valid_split(yi, groups, seed)
        self.validated_ = split is not None
        module, kwargs = self._module(Xt.shape[1], len(self.classes_))
        callbacks: list[Any] = []
        train_split: Any = None
        X_fit, y_fit = Xt, yi
        if split is not None:
            tr, va = split
            X_fit, y_fit = Xt[tr], yi[tr]
            train_split = predefined_split(SkorchDataset(Xt[va], yi[va]))
            callbacks.append(
                EarlyStopping(
                    monitor="valid_loss", patience=self.patience, load_best=True
                )
            )
        # fork_rng: seed torch's global generator (weight init, batch shuffling) for
        # this fit only, so a fixed random_state gives identical weights and the
        # caller's torch RNG state is left as it was.
        threads = torch.get_num_threads()
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            if self.num_threads is not None:
                torch.set_num_threads(self.num_threads)
            try:
                net = NeuralNetClassifier(
                    module,
                    **{f"module__{k}": v for k, v in kwargs.items()},
                    optimizer=torch.optim.Adam,
                    lr=self.lr,
                    optimizer__weight_decay=self.weight_decay,
                    max_epochs=self.max_epochs,
                    batch_size=self.batch_size,
                    train_split=train_split,
                    callbacks=callbacks,
                    classes=np.arange(len(self.classes_)),
                    iterator_train__shuffle=True,
                    verbose=0,
                    device="cpu",
                )
                net.fit(X_fit, y_fit)
            finally:
                torch.set_num_threads(threads)
        self.net_ = net
        self.module_: nn.Module = net.module_
        self.module_.eval()
        self.n_epochs_ = len(net.history)
        self.best_epoch_ = (
            int(np.argmin(net.history[:, "valid_loss"])) + 1
            if self.validated_
            else self.n_epochs_
        )
        self.n_parameters_ = int(sum(p.numel() for p in self.module_.parameters()))
        self.flops_per_window_ = _flops_per_window(self.module_, Xt.shape[1])
        return self

    def _features(self, X: ArrayLike) -> NDArray[np.float32]:
        check_is_fitted(self)
        # reset=False: keep n_features_in_ from fit, only check the shape.
        Xt = np.asarray(
            validate_data(self, X, reset=False, dtype=np.float32, order="C")
        )
        if self.scaler_ is not None:
            Xt = np.asarray(self.scaler_.transform(Xt), dtype=np.float32)
        return Xt

    def predict_proba(self, X: ArrayLike) -> NDArray[np.float32]:
        """Probability of each class (columns in ``classes_`` order) for every window.

        Parameters
        ----------
        X : array_like of shape (n_windows, n_features_in_)

        Returns
        -------
        ndarray of shape (n_windows, n_classes)
        """
        Xt = self._features(X)
        with torch.no_grad():
            proba = self.module_(torch.from_numpy(Xt)).numpy()
        return np.asarray(proba, dtype=np.float32)

    def predict(self, X: ArrayLike) -> NDArray[Any]:
        """The most probable class of every window.

        Parameters
        ----------
        X : array_like of shape (n_windows, n_features_in_)

        Returns
        -------
        ndarray of shape (n_windows,)
            Labels from ``classes_``.
        """
        check_is_fitted(self)  # before classes_ is read
        return np.asarray(self.classes_[np.argmax(self.predict_proba(X), axis=1)])


def _flops_per_window(module: nn.Module, n_features: int) -> int:
    """Floating-point operations of one forward pass on one window (torch's counter).

    Counts multiply-adds of matrix products and convolutions as 2 FLOPs (activations,
    softmax and the input scaling are left out: a few per input).
    """
    if isinstance(module, GRUModule):
        return module.flops_per_window()
    with torch.no_grad(), FlopCounterMode(display=False) as counter:
        module(torch.zeros(1, n_features))
    return int(counter.get_total_flops())


class WindowMLP(_WindowNet):
    """The paper's slip-type network: flattened window -> 50 sigmoid units -> softmax.

    Parameters
    ----------
    hidden_units : int
        Hidden units (paper: 50).
    activation : {"sigmoid", "tanh", "relu"}
        Hidden transfer function (paper: sigmoid).
    lr : float
        Adam learning rate (the paper does not say how it trained this network).
    weight_decay : float
        L2 penalty (Adam's ``weight_decay``).
    max_epochs : int
        Upper bound on passes over the training windows.
    batch_size : int
        Windows per gradient step.
    patience : int
        Epochs without a lower validation loss before stopping (the best epoch's
        weights are kept).
    validation_fraction : float in [0, 1)
        Share of training rows (whole trials when ``groups`` is given to ``fit``)
        held out for early stopping (paper: 20 %); 0 trains ``max_epochs`` epochs.
    standardize : bool
        Scale every input to zero mean and unit variance (fitted on the training
        windows): electrode counts sit near 2000-3700 with changes of tens of counts.
    num_threads : int or None
        torch threads while fitting (restored afterwards); None leaves torch's setting.
    random_state : int, RandomState or None
        Seeds weight initialisation, batch order and the validation split.

    Attributes
    ----------
    classes_ : ndarray of shape (n_classes,)
        Class labels, sorted.
    n_features_in_ : int
        Inputs per window (W x C).
    scaler_ : StandardScaler or None
        Input scaling, None without ``standardize``.
    net_ : skorch.NeuralNetClassifier
        The fitted skorch net (training history in ``net_.history``).
    module_ : torch.nn.Module
        The trained network (input: scaled window, float32; output: probabilities).
    validated_ : bool
        Whether a validation split (and early stopping) was used.
    n_epochs_ : int
        Epochs run.
    best_epoch_ : int
        Epoch whose weights were kept (1-based).
    n_parameters_ : int
        Trainable parameters of ``module_``.
    flops_per_window_ : int
        FLOPs of one forward pass on one window.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **_WindowNet._parameter_constraints,
        "hidden_units": [Interval(Integral, 1, None, closed="left")],
        "activation": [StrOptions(set(_ACTIVATIONS))],
    }

    def __init__(
        self,
        *,
        hidden_units: int = 50,
        activation: str = "sigmoid",
        lr: float = 1e-3,
        weight_decay: float = 0.0,
        max_epochs: int = 100,
        batch_size: int = 128,
        patience: int = 5,
        validation_fraction: float = 0.2,
        standardize: bool = True,
        num_threads: int | None = 1,
        random_state: int | np.random.RandomState | None = 0,
    ) -> None:
        self.hidden_units = hidden_units
        self.activation = activation
        self.lr = lr
        self.weight_decay = weight_decay
        self.max_epochs = max_epochs
        self.batch_size = batch_size
        self.patience = patience
        self.validation_fraction = validation_fraction
        self.standardize = standardize
        self.num_threads = num_threads
        self.random_state = random_state  # type: ignore[assignment]

    def _module(
        self, n_features: int, n_classes: int
    ) -> tuple[type[nn.Module], dict[str, Any]]:
        return MLPModule, {
            "n_features": n_features,
            "hidden_units": self.hidden_units,
            "n_classes": n_classes,
            "activation": self.activation,
        }


class WindowCNN(_WindowNet):
    """A small temporal model: 1-D convolutions over the window's frames, electrodes as channels.

    Takes the same flattened window as :class:`WindowMLP` and reshapes it inside to
    ``(n_channels, W)`` with ``W = n_features / n_channels``.

    Parameters
    ----------
    n_channels : int
        Channels per frame (19 BioTac electrodes, 24 on the BioTac SP); the input
        length must be a multiple of it.
    filters : int
        Convolution channels per layer.
    kernel_size : int
        Kernel length in frames (odd; 5 frames = 17 ms at 300 Hz).
    n_layers : int
        Convolution layers (ReLU after each), then a mean over time and a softmax layer.
    lr, weight_decay, max_epochs, batch_size, patience, validation_fraction, standardize, num_threads, random_state
        As in :class:`WindowMLP`.

    Attributes
    ----------
    classes_, n_features_in_, scaler_, net_, module_, validated_, n_epochs_, best_epoch_, n_parameters_, flops_per_window_
        As in :class:`WindowMLP`.
    width_ : int
        Frames per window, ``n_features_in_ / n_channels``.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **_WindowNet._parameter_constraints,
        "n_channels": [Interval(Integral, 1, None, closed="left")],
        "filters": [Interval(Integral, 1, None, closed="left")],
        "kernel_size": [Interval(Integral, 1, None, closed="left")],
        "n_layers": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(
        self,
        *,
        n_channels: int = 19,
        filters: int = 16,
        kernel_size: int = 5,
        n_layers: int = 2,
        lr: float = 1e-3,
        weight_decay: float = 0.0,
        max_epochs: int = 100,
        batch_size: int = 128,
        patience: int = 5,
        validation_fraction: float = 0.2,
        standardize: bool = True,
        num_threads: int | None = 1,
        random_state: int | np.random.RandomState | None = 0,
    ) -> None:
        self.n_channels = n_channels
        self.filters = filters
        self.kernel_size = kernel_size
        self.n_layers = n_layers
        self.lr = lr
        self.weight_decay = weight_decay
        self.max_epochs = max_epochs
        self.batch_size = batch_size
        self.patience = patience
        self.validation_fraction = validation_fraction
        self.standardize = standardize
        self.num_threads = num_threads
        self.random_state = random_state  # type: ignore[assignment]

    def _module(
        self, n_features: int, n_classes: int
    ) -> tuple[type[nn.Module], dict[str, Any]]:
        self._frames(n_features)
        if self.kernel_size % 2 == 0:
            raise ValueError(
                f"kernel_size must be odd (same-length padding); got {self.kernel_size}"
            )
        return TemporalCNNModule, {
            "n_channels": self.n_channels,
            "width": self.width_,
            "n_classes": n_classes,
            "filters": self.filters,
            "kernel_size": self.kernel_size,
            "n_layers": self.n_layers,
        }


class WindowGRU(_WindowNet):
    """A recurrent temporal model: a GRU steps through the window's frames, electrodes as inputs.

    Takes the same flattened window as :class:`WindowMLP`, reads it as ``W`` frames
    of ``n_channels`` and classifies from the GRU's state after the last frame.
    The state starts at zero for every window (none is carried between windows);
    the ONNX graph (:mod:`slipkit.export.torch`) is "whole window in, class out".

    Parameters
    ----------
    n_channels : int
        Channels per frame (19 BioTac, 24 BioTac SP).
    hidden_units : int
        GRU state size.
    n_layers : int
        Stacked GRU layers.
    lr, weight_decay, max_epochs, batch_size, patience, validation_fraction, standardize, num_threads, random_state
        As in :class:`WindowMLP`.

    Attributes
    ----------
    classes_, n_features_in_, scaler_, net_, module_, validated_, n_epochs_, best_epoch_, n_parameters_, flops_per_window_
        As in :class:`WindowMLP` (FLOPs in closed form: :meth:`GRUModule.flops_per_window`).
    width_ : int
        Frames per window, ``n_features_in_ / n_channels``.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        **_WindowNet._parameter_constraints,
        "n_channels": [Interval(Integral, 1, None, closed="left")],
        "hidden_units": [Interval(Integral, 1, None, closed="left")],
        "n_layers": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(
        self,
        *,
        n_channels: int = 19,
        hidden_units: int = 32,
        n_layers: int = 1,
        lr: float = 3e-3,
        weight_decay: float = 0.0,
        max_epochs: int = 60,
        batch_size: int = 128,
        patience: int = 8,
        validation_fraction: float = 0.2,
        standardize: bool = True,
        num_threads: int | None = 1,
        random_state: int | np.random.RandomState | None = 0,
    ) -> None:
        self.n_channels = n_channels
        self.hidden_units = hidden_units
        self.n_layers = n_layers
        self.lr = lr
        self.weight_decay = weight_decay
        self.max_epochs = max_epochs
        self.batch_size = batch_size
        self.patience = patience
        self.validation_fraction = validation_fraction
        self.standardize = standardize
        self.num_threads = num_threads
        self.random_state = random_state  # type: ignore[assignment]

    def _module(
        self, n_features: int, n_classes: int
    ) -> tuple[type[nn.Module], dict[str, Any]]:
        self._frames(n_features)
        return GRUModule, {
            "n_channels": self.n_channels,
            "width": self.width_,
            "n_classes": n_classes,
            "hidden_units": self.hidden_units,
            "n_layers": self.n_layers,
        }
