"""TacTip trials and datasets to (X, y, t) arrays of pin-velocity features.

Reads the ``pins`` stream (``x0 .. x{N-1}`` then ``y0 .. y{N-1}``, mm, NaN for a
pin not detected; see :mod:`slipkit.physics.tactip`) and the ``slip_onset_s``
label (s) of the ``tactip_gravity_drop`` scene or a recording in the same layout.
Row ``k`` of the output is velocity frame ``k`` (camera frame ``k`` to ``k + 1``);
see :mod:`slipkit.features.pins` for the onset convention and the missing-pin policy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from slipkit.features.pins import (
    Variant,
    frame_labels,
    onset_velocity_index,
    pin_velocities,
    velocity_features,
)
from slipkit.physics.tactip import pin_channels, split_pins

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


#: Names of :func:`pooled_features`, in column order.
POOLED_NAMES: tuple[str, ...] = (
    "speed_mean",
    "speed_rms",
    "speed_max",
    "resultant",
    "velocity_mean",
    "alignment",
)


def pooled_features(X: NDArray[np.float64] | list[list[float]]) -> NDArray[np.float64]:
    """Pin-count-independent statistics of per-pin ``dr_dtheta`` feature rows.

    A pin is *present* in a velocity frame when its ``dr`` is above 0: the per-pin
    features give a missing (NaN) pin ``dr = 0`` and no angle
    (:mod:`slipkit.features.pins`), so every statistic below is a mean over the
    present pins only (a still pin, exactly 0 mm/frame, has no direction either).
    The angles may be shifted by their circular mean (the paper's features) or
    not: every statistic is invariant to a common rotation.

    Parameters
    ----------
    X : array_like of shape (n_frames, 2 N)
        ``dr_0 .. dr_{N-1}`` (mm/frame) then ``dtheta_0 .. dtheta_{N-1}`` (rad),
        any pin count ``N``.

    Returns
    -------
    ndarray of shape (n_frames, 6)
        Columns :data:`POOLED_NAMES`: mean, RMS and largest pin speed (mm/frame);
        the resultant length of the unit velocities ``R = |mean exp(i dtheta)|``
        (0..1, 1 = every present pin moves the same way); the length of the mean
        velocity vector ``|mean dr exp(i dtheta)|`` (mm/frame); and
        ``speed_mean * R`` (mm/frame), how fast the pins move together. A frame
        with no present pin is all zeros.
    """
    arr = np.asarray(X, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < 2 or arr.shape[1] % 2:
        raise ValueError(
            "pooled features need per-pin dr_dtheta rows of shape (n_frames, 2 N); "
            f"got {arr.shape}"
        )
    n = arr.shape[1] // 2
    dr, theta = arr[:, :n], arr[:, n:]
    present = dr > 0
    count = np.maximum(present.sum(axis=1), 1).astype(np.float64)
    drp = np.where(present, dr, 0.0)
    c = np.where(present, np.cos(theta), 0.0)
    s = np.where(present, np.sin(theta), 0.0)
    speed_mean = drp.sum(axis=1) / count
    speed_rms = np.sqrt((drp * drp).sum(axis=1) / count)
    speed_max = drp.max(axis=1)
    resultant = np.hypot(c.sum(axis=1), s.sum(axis=1)) / count
    velocity = np.hypot((drp * c).sum(axis=1), (drp * s).sum(axis=1)) / count
    return np.stack(
        [speed_mean, speed_rms, speed_max, resultant, velocity, speed_mean * resultant],
        axis=1,
    )
