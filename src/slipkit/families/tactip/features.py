"""TacTip trials and datasets to (X, y, t) arrays of pin-velocity features.

Reads the ``pins`` stream (``x0 .. x{N-1}`` then ``y0 .. y{N-1}``, mm, NaN for a
pin not detected; see :mod:`slipkit.families.tactip.physics`) and the ``slip_onset_s``
label (s) of the ``tactip_gravity_drop`` scene or a recording in the same layout.
Row ``k`` of the output is velocity frame ``k`` (camera frame ``k`` to ``k + 1``);
see :mod:`slipkit.features.pins` for the onset convention and the missing-pin policy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from slipkit.families.tactip.physics import pin_channels, split_pins
from slipkit.features.pins import (
    Variant,
    frame_labels,
    onset_velocity_index,
    pin_velocities,
    velocity_features,
)

if TYPE_CHECKING:  # the data layer imports pandas; this module only reads arrays
    from slipkit.data.dataset import Dataset, Trial


class TrialFeatures(NamedTuple):
    """Features of one trial, one row per velocity frame.

    Attributes
    ----------
    X : ndarray (n_frames - 1, F)
        Features (:func:`~slipkit.features.pins.velocity_features`).
    y : ndarray of str (n_frames - 1,)
        'slip' or 'static' (:func:`~slipkit.features.pins.frame_labels`).
    t : ndarray (n_frames - 1,)
        Time at which each velocity frame is available (its later camera frame), s.
    onset_index : int or None
        Onset velocity frame, None for a trial without slip in the recording.
    """

    X: NDArray[np.float64]
    y: NDArray[np.str_]
    t: NDArray[np.float64]
    onset_index: int | None


class DatasetFeatures(NamedTuple):
    """Features of many trials, concatenated in dataset order.

    Attributes
    ----------
    X, y, t : ndarray
        As in :class:`TrialFeatures`, stacked over trials (``t`` in s from each
        trial's start).
    groups : ndarray of str
        Trial id of every row, so splits and cross-validation keep trials apart
        (``GroupKFold(...).split(X, y, groups)``).
    """

    X: NDArray[np.float64]
    y: NDArray[np.str_]
    t: NDArray[np.float64]
    groups: NDArray[np.str_]


def trial_features(
    trial: Trial,
    *,
    variant: Variant = "dr_dtheta",
    shift_angles: bool = True,
    n_slip: int | None = 4,
    missing_count: bool = False,
    stream: str = "pins",
    label: str = "slip_onset_s",
) -> TrialFeatures:
    """Pin-velocity features and frame labels of one TacTip trial.

    Parameters
    ----------
    trial : Trial
        Holds ``stream`` (columns ``t`` in s, then ``x0..``, ``y0..`` in mm) and the
        ``label`` onset (s; NaN or absent: no slip, every frame 'static').
    variant, shift_angles, missing_count
        Passed to :func:`~slipkit.features.pins.velocity_features`.
    n_slip : int or None
        Velocity frames labelled 'slip' from the onset on (None: all of them).
    stream, label : str
        Names of the pins stream and of the onset label.

    Returns
    -------
    TrialFeatures
        ``(X, y, t, onset_index)``; unpack ``X, y, t, _ = trial_features(...)``.
    """
    if stream not in trial.streams:
        raise KeyError(
            f"trial {trial.trial_id!r} has no stream {stream!r}; streams: {sorted(trial.streams)}"
        )
    table = trial.streams[stream]
    n_pins = (len(table.columns) - 1) // 2
    if n_pins < 1 or list(table.columns) != ["t", *pin_channels(n_pins)]:
        raise ValueError(
            f"trial {trial.trial_id!r}, stream {stream!r}: expected columns t, x0..x{{N-1}}, "
            f"y0..y{{N-1}}; got {list(table.columns)[:4]}... ({len(table.columns)} columns)"
        )
    if len(table) < 2:
        raise ValueError(
            f"trial {trial.trial_id!r}: {len(table)} frames; velocities need >= 2"
        )
    t = table["t"].to_numpy(dtype=np.float64)
    x, y = split_pins(table.drop(columns="t").to_numpy(dtype=np.float64))
    dxy = pin_velocities(np.stack([x, y], axis=-1))
    X = velocity_features(
        dxy, variant, shift_angles=shift_angles, missing_count=missing_count
    )
    onset = trial.labels.get(label, np.nan)
    onset_index = onset_velocity_index(t, float(onset))
    labels = frame_labels(len(dxy), onset_index, n_slip)
    return TrialFeatures(X, labels, t[1:], onset_index)


def dataset_features(
    dataset: Dataset,
    *,
    variant: Variant = "dr_dtheta",
    shift_angles: bool = True,
    n_slip: int | None = 4,
    missing_count: bool = False,
    stream: str = "pins",
    label: str = "slip_onset_s",
) -> DatasetFeatures:
    """:func:`trial_features` of every trial, concatenated, with trial ids as groups.

    Parameters are those of :func:`trial_features`.

    Returns
    -------
    DatasetFeatures
        ``(X, y, t, groups)``; ``groups[i]`` is the trial id of row ``i``.
    """
    ids: list[str] = []
    parts: list[TrialFeatures] = []
    for trial in dataset:
        ids.append(trial.trial_id)
        parts.append(
            trial_features(
                trial,
                variant=variant,
                shift_angles=shift_angles,
                n_slip=n_slip,
                missing_count=missing_count,
                stream=stream,
                label=label,
            )
        )
    if not parts:
        raise ValueError(f"dataset {dataset.name or dataset.sensor!r} has no trials")
    return DatasetFeatures(
        np.concatenate([p.X for p in parts]),
        np.concatenate([p.y for p in parts]),
        np.concatenate([p.t for p in parts]),
        np.repeat(np.asarray(ids, dtype=str), [len(p.y) for p in parts]),
    )
