"""Features computed from sensor streams (numpy only, so the runtime can reuse them)."""

from slipkit.features.pins import (
    SLIP,
    STATIC,
    circular_mean,
    feature_names,
    frame_labels,
    onset_velocity_index,
    pin_velocities,
    velocity_features,
    wrap_angle,
)
from slipkit.features.tactip import (
    DatasetFeatures,
    TrialFeatures,
    dataset_features,
    trial_features,
)

__all__ = [
    "SLIP",
    "STATIC",
    "DatasetFeatures",
    "TrialFeatures",
    "circular_mean",
    "dataset_features",
    "feature_names",
    "frame_labels",
    "onset_velocity_index",
    "pin_velocities",
    "trial_features",
    "velocity_features",
    "wrap_angle",
]
