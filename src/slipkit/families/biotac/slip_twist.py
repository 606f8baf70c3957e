"""Analytic linear-vs-rotational slip classifier on BioTac electrode windows.

The slip-type task (:class:`~slipkit.train.tasks.slip_type.WindowClassification`,
``comparison=biotac_slip_type``; Su et al. 2015, Sec. IV-C) asks whether a window shows
linear or rotational slip. The skin dragged by a slipping object shifts the electrode
pattern by ``w_i (u(p_i) . d)`` (:func:`slipkit.families.biotac.effects.slip_deformation`):
under linear slip ``u`` is one drag along the load direction ``d``, so every electrode
near the contact changes with the same sign; under rotation ``u = twist n x (p - c)``
is antisymmetric about the load line, so electrodes on either side change with opposite
signs. :class:`SlipTwistClassifier` scores a window by the share of its electrode change
that cancels out,

    D_i = mean(x[-k:, i]) - mean(x[:k, i]),   k = max(1, width // 4)   (counts)
    R   = 1 - |sum_i D_i| / sum_i |D_i|                                  (0 .. 1)

(``R = 0``: every electrode moves together -- translation; ``R -> 1``: the changes
cancel -- a twist), and chooses the threshold on the training windows' ROC (rotational
against linear, Youden's J, as :mod:`slipkit.baselines.base`). Differencing within the
window removes per-trial electrode offsets; averaging ``k`` frames at each end damps the
noise. It assumes the contact lies off no symmetry line that would cancel a drag (a
centred linear drag changes every electrode with one sign) and that the grip force is
roughly steady over the window (a squeeze changes every electrode with one sign, which
reads as linear). Written here because no library computes it: it is two lines of numpy.
"""

from __future__ import annotations

import warnings
from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.metrics import roc_curve
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_array, check_is_fitted

from slipkit.errors import SlipkitError


class SlipTwistClassifier(ClassifierMixin, BaseEstimator):
    """Linear vs rotational slip from the cancelling share of the electrode change.

    See the module doc for the statistic.

    Parameters
    ----------
    n_channels : int
        Channels per frame (BioTac: 19 electrodes); a window row holds
        ``width * n_channels`` values, frame-major
        (:func:`slipkit.features.windows.sliding_windows`).
    rotational_class : str
        The label of rotational slip (the task's ``slip_class``: ``"rotational"``); the
        other training class is the linear one.

    Attributes
    ----------
    classes_ : ndarray of str
        The two training classes, sorted.
    threshold_ : float
        Twist share ``R`` (dimensionless, 0..1) at and above which a window is rotational.
    linear_class_ : str
        The other training class.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "n_channels": [Interval(Integral, 1, None, closed="left")],
        "rotational_class": [str],
    }

    def __init__(
        self, n_channels: int = 19, rotational_class: str = "rotational"
    ) -> None:
        self.n_channels = n_channels
        self.rotational_class = rotational_class

    def twist_share(self, X: ArrayLike) -> NDArray[np.float64]:
        """Share ``R`` of each window's electrode change that cancels out (0..1).

        Parameters
        ----------
        X : array_like of shape (n_windows, width * n_channels)
            Windows, frame-major (electrode counts).

        Returns
        -------
        ndarray of shape (n_windows,)
            0 where the window holds one frame or no change.
        """
        A = check_array(X, dtype=np.float64, ensure_all_finite="allow-nan")
        if A.shape[1] % self.n_channels:
            raise SlipkitError(
                f"SlipTwistClassifier: a window row holds {A.shape[1]} values, not a "
                f"multiple of n_channels={self.n_channels}"
            )
        W = A.reshape(len(A), -1, self.n_channels)
        k = max(1, W.shape[1] // 4)
        with warnings.catch_warnings():  # an all-NaN electrode: 'Mean of empty slice'
            warnings.simplefilter("ignore", RuntimeWarning)
            D = np.nanmean(W[:, -k:], axis=1) - np.nanmean(W[:, :k], axis=1)
        D = np.where(np.isfinite(D), D, 0.0)
        total = np.abs(D).sum(axis=1)
        net = np.abs(D.sum(axis=1))
        safe = np.where(total > 0, total, 1.0)
        return np.where(total > 0, 1.0 - net / safe, 0.0)

    def fit(self, X: ArrayLike, y: ArrayLike) -> SlipTwistClassifier:
        """Choose the threshold on ``R`` on the training windows' ROC (Youden's J).

        Raises
        ------
        SlipkitError
            When the training labels are not ``rotational_class`` and one other class.
        """
        self._validate_params()
        labels = np.asarray(y).astype(str)
        classes = np.unique(labels)
        if len(classes) != 2 or self.rotational_class not in classes:
            raise SlipkitError(
                "SlipTwistClassifier: the training windows need two classes, one of them "
                f"rotational_class={self.rotational_class!r}; classes: {classes.tolist()}"
            )
        rot = labels == self.rotational_class
        r = self.twist_share(X)
        fpr, tpr, thr = roc_curve(rot, r)
        best = int(np.argmax(tpr - fpr))
        self.threshold_ = float(thr[best]) if np.isfinite(thr[best]) else float(r.max())
        self.linear_class_ = str(classes[classes != self.rotational_class][0])
        self.classes_ = classes
        return self

    def decision_function(self, X: ArrayLike) -> NDArray[np.float64]:
        """``R`` minus the threshold: positive for rotational slip (dimensionless)."""
        check_is_fitted(self, "threshold_")
        return self.twist_share(X) - self.threshold_

    def predict(self, X: ArrayLike) -> NDArray[np.str_]:
        """The rotational class at / above the threshold, the linear class below."""
        rot = self.decision_function(X) >= 0
        return np.where(rot, self.rotational_class, self.linear_class_).astype(str)


__all__ = ["SlipTwistClassifier"]
