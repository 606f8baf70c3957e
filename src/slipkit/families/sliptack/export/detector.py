"""The SlipTack slip decision as a speed threshold (mm/s) over the speed estimate, and its
exporter: the speed graph of :mod:`slipkit.families.sliptack.export.speed` with the threshold applied.
"""

from __future__ import annotations

from numbers import Real
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils._param_validation import HasMethods, Interval
from sklearn.utils.validation import check_is_fitted

from slipkit.export.detectors import (
    DetectorGraph,
)
from slipkit.export.registry import (
    DEFAULT_OPSET,
    register_exporter,
)
from slipkit.families.sliptack.export.speed import FloatArray, export_stick_slip_speed
from slipkit.families.sliptack.speed import (
    StickSlipSpeed,
)


# -- the decision: a speed threshold --------------------------------------------------
class SpeedSlipDetector(ClassifierMixin, BaseEstimator):
    """Slip where the SlipTack speed estimate reaches a threshold (mm/s).

    Wraps a fitted :class:`StickSlipSpeed` so that the speed has a decision rule:
    ``decision_function`` is the speed (mm/s) per sample, ``-inf`` where undefined
    (warm-up, no peak, saturation), and a sample is slip (``1``) where it is ``>=
    threshold``, as every :class:`~slipkit.baselines.base.StreamDetector`.

    Parameters
    ----------
    speed : StickSlipSpeed
        A fitted speed estimator.
    threshold : float
        Speed (mm/s) at and above which the object slips; 0: whenever a stick-slip
        frequency is found.

    Attributes
    ----------
    threshold_ : float
        ``threshold`` (mm/s).
    classes_ : ndarray
        ``[0, 1]`` (no slip, slip).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "speed": [HasMethods(["predict", "frequency"])],
        "threshold": [Interval(Real, 0, None, closed="left")],
    }

    def __init__(self, *, speed: StickSlipSpeed, threshold: float = 0.0) -> None:
        self.speed = speed
        self.threshold = threshold

    def fit(
        self, X: ArrayLike | None = None, y: ArrayLike | None = None
    ) -> SpeedSlipDetector:
        """Check the wrapped estimator is fitted and fix the threshold (no data used)."""
        self._validate_params()
        check_is_fitted(self.speed, "stick_length_m_")
        self.threshold_ = float(self.threshold)
        self.classes_ = np.array([0, 1])
        return self

    def decision_function(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> FloatArray:
        """Speed per sample (mm/s) of recordings ``X`` (n_samples, 1); ``-inf`` where undefined."""
        check_is_fitted(self, "threshold_")
        v = self.speed.predict(X, segments=segments)
        return np.where(np.isfinite(v), v, -np.inf)

    def predict(
        self, X: ArrayLike, *, segments: ArrayLike | None = None
    ) -> NDArray[np.int_]:
        """1 (slip) where the speed is ``>= threshold_``, else 0."""
        return (self.decision_function(X, segments=segments) >= self.threshold_).astype(
            int
        )


def export_speed_slip_detector(
    detector: SpeedSlipDetector,
    *,
    dft_dtype: str = "float32",
    incremental: bool = False,
    prepare: bool = False,
    opset: int = DEFAULT_OPSET,
) -> DetectorGraph:
    """Export a fitted :class:`SpeedSlipDetector`: the speed graph with its threshold."""
    check_is_fitted(detector, "threshold_")
    return export_stick_slip_speed(
        detector.speed,
        threshold=detector.threshold_,
        dft_dtype=dft_dtype,
        incremental=incremental,
        prepare=prepare,
        opset=opset,
    )


register_exporter(SpeedSlipDetector, export_speed_slip_detector)
