"""Analytic motion-vs-touch classifier on electrode windows: the window's change energy.

The direction-of-slip task (:class:`~slipkit.train.tasks.slip_type.WindowClassification`,
``comparison=dos_real``) asks a learned model which of seven classes a window shows
(``n e s w cw aw`` motion, ``t`` a touch without motion). An analytic rule cannot name a
direction, but it can tell motion from a touch: a sliding object keeps changing the
electrode values, a resting touch does not. :class:`ElectrodeEnergyClassifier` scores a
window by the RMS of its frame-to-frame change over all channels,

    E = sqrt(mean_{t, c} (x[t + 1, c] - x[t, c])^2)          (electrode counts / frame),

chooses the threshold on the training windows' ROC (motion against touch, Youden's J),
and predicts the touch class below it and, above it, the most frequent motion class of
the training windows (the best a direction-blind rule can do on the 7-class score). It
is the analytic floor of the window task: what a learned model adds beyond "is it
moving".
"""

from __future__ import annotations

from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.metrics import roc_curve
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_array, check_is_fitted

from slipkit.errors import SlipkitError


class ElectrodeEnergyClassifier(ClassifierMixin, BaseEstimator):
    """Motion vs touch from the change energy of an electrode window (see the module doc).

    Parameters
    ----------
    n_channels : int
        Channels per frame; a window row holds ``width * n_channels`` values, frame-major
        (:func:`slipkit.features.windows.sliding_windows`).
    touch_class : str
        The class label of a touch without motion (BioTacSP-DoS: ``"t"``).

    Attributes
    ----------
    classes_ : ndarray of str
        Every class seen in training.
    threshold_ : float
        Energy (counts / frame) at and above which a window is motion.
    motion_class_ : str
        The class predicted for motion: the most frequent non-touch training class.
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "n_channels": [Interval(Integral, 1, None, closed="left")],
        "touch_class": [str],
    }

    def __init__(self, n_channels: int = 24, touch_class: str = "t") -> None:
        self.n_channels = n_channels
        self.touch_class = touch_class

    def energy(self, X: ArrayLike) -> NDArray[np.float64]:
        """Change energy of every window (counts / frame); NaN steps are skipped.

        Parameters
        ----------
        X : array_like of shape (n_windows, width * n_channels)
            Windows, frame-major.

        Returns
        -------
        ndarray of shape (n_windows,)
        """
        A = check_array(X, dtype=np.float64, ensure_all_finite="allow-nan")
        if A.shape[1] % self.n_channels or A.shape[1] < 2 * self.n_channels:
            raise SlipkitError(
                f"ElectrodeEnergyClassifier: a window row holds {A.shape[1]} values, "
                f"not a multiple (>= 2 frames) of n_channels={self.n_channels}"
            )
        W = A.reshape(len(A), -1, self.n_channels)
        d2 = np.diff(W, axis=1) ** 2
        with np.errstate(invalid="ignore"):
            e = np.sqrt(np.nanmean(d2.reshape(len(A), -1), axis=1))
        return np.where(np.isfinite(e), e, 0.0)

    def fit(self, X: ArrayLike, y: ArrayLike) -> ElectrodeEnergyClassifier:
        """Choose the motion threshold on the training windows' ROC (Youden's J).

        Raises
        ------
        SlipkitError
            When the training windows hold no touch or no motion window.
        """
        self._validate_params()
        labels = np.asarray(y).astype(str)
        motion = labels != self.touch_class
        if motion.all() or not motion.any():
            raise SlipkitError(
                "ElectrodeEnergyClassifier: the training windows need both touch "
                f"({self.touch_class!r}) and motion windows; classes: "
                f"{sorted(set(labels))}"
            )
        e = self.energy(X)
        fpr, tpr, thr = roc_curve(motion, e)
        best = int(np.argmax(tpr - fpr))
        self.threshold_ = float(thr[best]) if np.isfinite(thr[best]) else float(e.max())
        values, counts = np.unique(labels[motion], return_counts=True)
        self.motion_class_ = str(values[np.argmax(counts)])
        self.classes_ = np.unique(labels)
        return self

    def decision_function(self, X: ArrayLike) -> NDArray[np.float64]:
        """Energy minus the threshold: positive for motion (counts / frame)."""
        check_is_fitted(self, "threshold_")
        return self.energy(X) - self.threshold_

    def predict(self, X: ArrayLike) -> NDArray[np.str_]:
        """The touch class below the threshold, the most frequent motion class at / above it."""
        moving = self.decision_function(X) >= 0
        return np.where(moving, self.motion_class_, self.touch_class).astype(str)


__all__ = ["ElectrodeEnergyClassifier"]
