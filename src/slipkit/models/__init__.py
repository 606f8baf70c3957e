"""Slip detectors as scikit-learn estimators, and the online rules that use them.

``slipkit.models.online`` is numpy only (the gripper-PC runtime may import it);
the estimators import scikit-learn, so they load on first access.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from slipkit.models.online import (
    debounce,
    detection_delay,
    first_detection,
    frames_to_ms,
)

if TYPE_CHECKING:
    from slipkit.models.force import (
        ForceMLP,
        LocalLinearRegressor,
        WeightedNormalsRegressor,
    )
    from slipkit.models.svm import TacTipSVM

__all__ = [
    "ForceMLP",
    "LocalLinearRegressor",
    "TacTipSVM",
    "WeightedNormalsRegressor",
    "debounce",
    "detection_delay",
    "first_detection",
    "frames_to_ms",
]


def __getattr__(name: str) -> Any:
    # Lazy: importing slipkit.models.online must not pull in scikit-learn.
    if name == "TacTipSVM":
        from slipkit.models.svm import TacTipSVM

        return TacTipSVM
    if name in ("ForceMLP", "LocalLinearRegressor", "WeightedNormalsRegressor"):
        from slipkit.models import force

        return getattr(force, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
