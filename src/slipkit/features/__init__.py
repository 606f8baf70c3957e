"""Features computed from sensor streams (numpy only, so the runtime can reuse them); a
family's trial and dataset readers live in its folder (``slipkit.families.<family>``)."""

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

__all__ = [
    "SLIP",
    "STATIC",
    "circular_mean",
    "feature_names",
    "frame_labels",
    "onset_velocity_index",
    "pin_velocities",
    "velocity_features",
    "wrap_angle",
]
