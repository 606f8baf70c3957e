"""Per-electrode window statistics as a scikit-learn transformer.

A flattened window (:func:`slipkit.features.windows.sliding_windows`: ``W`` frames of
``C`` channels, time-major) becomes a few numbers per channel: ``mean``, ``std``
(population), ``min``, ``max``, ``last_first`` (last frame minus first) and
``mean_abs_diff`` (mean absolute frame-to-frame change). The output is stat-major:
the ``C`` means, then the ``C`` standard deviations, and so on.

``subtract_first`` (off by default, and a declared hyper-parameter so a model
selection can choose it) subtracts the window's own first frame before the
statistics: the level of the static contact is gone and only what changed within
the window remains (``std``, ``last_first`` and ``mean_abs_diff`` do not change;
``mean``, ``min`` and ``max`` become relative to the first frame). Subtracting the
*trial's* first frame instead is the task's ``mode: trial``
(:class:`slipkit.train.tasks.slip_type.WindowClassification`), which the runtime
does with its ``baseline_first`` op before the graph.

The transformer exports to ONNX as plain ops (Reshape, Slice, Reduce*, Abs, Sqrt,
Concat; :mod:`slipkit.export.window_stats` registers the skl2onnx converter), so a
``Pipeline(WindowStatistics, StandardScaler, LogisticRegression)`` exports whole.
"""

from __future__ import annotations

from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, TransformerMixin, _fit_context
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted, validate_data

__all__ = ["STATS", "WindowStatistics", "window_statistics"]

#: the statistics, in output order
STATS: tuple[str, ...] = ("mean", "std", "min", "max", "last_first", "mean_abs_diff")


def window_statistics(
    windows: NDArray[np.floating], stats: tuple[str, ...] = STATS
) -> NDArray[np.float64]:
    """Statistics over the time axis of ``windows`` of shape (n, W, C) -> (n, len(stats) * C).

    ``mean_abs_diff`` of a one-frame window is 0 (no change was seen).
    """
    v = np.asarray(windows, dtype=np.float64)
    out = []
    for s in stats:
        if s == "mean":
            out.append(v.mean(axis=1))
        elif s == "std":
            out.append(v.std(axis=1))
        elif s == "min":
            out.append(v.min(axis=1))
        elif s == "max":
            out.append(v.max(axis=1))
        elif s == "last_first":
            out.append(v[:, -1] - v[:, 0])
        elif s == "mean_abs_diff":
            out.append(
                np.abs(np.diff(v, axis=1)).mean(axis=1)
                if v.shape[1] > 1
                else np.zeros(v[:, 0].shape)
            )
        else:
            raise ValueError(f"unknown window statistic {s!r}; known: {STATS}")
    return np.concatenate(out, axis=1)


class WindowStatistics(TransformerMixin, BaseEstimator):
    """Flattened windows -> per-channel statistics (stat-major).

    Parameters
    ----------
    n_channels : int
        Channels per frame (24 BioTac SP electrodes, 19 BioTac); the input length
        must be a multiple of it.
    stats : sequence of str
        Statistics to compute, in output order (a subset of :data:`STATS`).
    subtract_first : bool
        Subtract each window's first frame before the statistics (dynamics within
        the window only; see the module notes). Off by default.

    Attributes
    ----------
    n_features_in_ : int
        Inputs per window (W x C).
    width_ : int
        Frames per window W.
    n_features_out_ : int
        ``len(stats) * n_channels``.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "n_channels": [Interval(Integral, 1, None, closed="left")],
        "stats": [list, tuple],
        "subtract_first": ["boolean"],
    }

    def __init__(
        self,
        *,
        n_channels: int = 24,
        stats: tuple[str, ...] | list[str] = STATS,
        subtract_first: bool = False,
    ) -> None:
        self.n_channels = n_channels
        self.stats = stats
        self.subtract_first = subtract_first

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X: ArrayLike, y: ArrayLike | None = None) -> WindowStatistics:
        """Check the window shape (nothing is learned).

        Parameters
        ----------
        X : array_like of shape (n_windows, W * n_channels)
        y : ignored

        Returns
        -------
        self
        """
        Xa = np.asarray(validate_data(self, X, dtype=np.float64))
        unknown = [s for s in self.stats if s not in STATS]
        if unknown or not len(self.stats):
            raise ValueError(
                f"stats must be a non-empty subset of {STATS}; got {list(self.stats)}"
            )
        if Xa.shape[1] % self.n_channels:
            raise ValueError(
                f"{Xa.shape[1]} inputs per window is not a multiple of "
                f"n_channels={self.n_channels}; set n_channels to the stream's channel count"
            )
        self.width_ = Xa.shape[1] // self.n_channels
        self.n_features_out_ = len(self.stats) * self.n_channels
        return self

    def transform(self, X: ArrayLike) -> NDArray[np.float64]:
        """Statistics of every window.

        Parameters
        ----------
        X : array_like of shape (n_windows, n_features_in_)

        Returns
        -------
        ndarray of shape (n_windows, n_features_out_)
        """
        check_is_fitted(self)
        # reset=False: keep n_features_in_ from fit, only check the shape.
        Xa = np.asarray(validate_data(self, X, reset=False, dtype=np.float64))
        v = Xa.reshape(len(Xa), self.width_, self.n_channels)
        if self.subtract_first:
            v = v - v[:, :1]
        return window_statistics(v, tuple(self.stats))

    def get_feature_names_out(self, input_features: Any = None) -> NDArray[np.object_]:
        """``<stat>_c<channel>`` for every output column."""
        check_is_fitted(self)
        return np.asarray(
            [f"{s}_c{c}" for s in self.stats for c in range(self.n_channels)],
            dtype=object,
        )
