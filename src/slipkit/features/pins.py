"""TacTip pin-velocity features (James, Pestell, Lepora 2018, RA-L 3(4), Sec. III-B).

numpy only: the gripper-PC runtime computes the same features from live camera
frames, so this module must not import pandas, scikit-learn or torch.

Frames, velocity frames and the onset
-------------------------------------
A trial has camera frames ``0 .. T-1`` at times ``t_0 .. t_{T-1}`` (s) holding the
pin centres (mm). *Velocity frame* ``k`` is the difference ``frame k+1 - frame k``
(mm per frame): it covers the interval ``(t_k, t_{k+1}]`` and becomes available
at ``t_{k+1}``, so a trial of ``T`` frames gives ``T - 1`` velocity frames.
The *onset velocity frame* is the one whose interval holds the slip onset,
``t_k < onset_s <= t_{k+1}`` (:func:`onset_velocity_index`): the first velocity
frame that can see the snap-back. :func:`frame_labels` marks it and the next
``n_slip - 1`` velocity frames 'slip' (the paper's "first N frames" of the slip
class, N = 4 best), every other velocity frame 'static'.

Features
--------
Per pin ``i``: ``dr_i = hypot(dx_i, dy_i)`` (mm/frame) and
``dtheta_i = atan2(dy_i, dx_i)`` (rad), the angles then shifted by their
per-frame circular mean and wrapped back to ``(-pi, pi]`` -- the paper's
"shifted to have a mean of zero ... removing all angular dependence". A plain
arithmetic mean of angles is wrong near +-pi (the mean of 179 deg and -179 deg is
180 deg, not 0), hence the circular mean ``atan2(mean sin, mean cos)``.

Undefined angles (policy)
-------------------------
A pin whose velocity is NaN (not detected in either frame of the pair) or exactly
zero (``atan2(0, 0)`` is 0, but ``atan2(-0.0, -0.0)`` is -pi: the direction of a
zero vector is undefined) has no angle. Such a pin

* is left out of the frame's circular mean,
* gets ``dtheta = 0`` (rad): "no direction", the centre of the shifted range,
* gets ``dr = 0`` (mm/frame) when missing (a missing pin is treated as still).

``velocity_features(..., missing_count=True)`` appends the number of missing pins
per velocity frame as one more feature, so a model can learn to discount frames
with many gaps. NaN never reaches the output.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
Variant = Literal["dr_dtheta", "dr", "dtheta"]
VARIANTS: tuple[str, ...] = ("dr_dtheta", "dr", "dtheta")

#: Class names of velocity frames (the paper's 'slip' and 'static' classes).
SLIP = "slip"
STATIC = "static"

#: Resultant length (0..1) below which a frame's mean direction is numerical noise:
#: a sum of up to a few hundred unit vectors that cancel leaves ~1e-14 of rounding,
#: so anything under 1e-9 carries no direction and the mean is defined as 0 rad.
RESULTANT_EPS = 1e-9


def _pin_array(values: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim < 2 or arr.shape[-1] != 2:
        raise ValueError(
            f"{name} must have shape (..., N, 2) with (x, y) last; got {arr.shape}"
        )
    return arr


def pin_velocities(frames: ArrayLike) -> FloatArray:
    """Frame-to-frame pin displacement (the paper's "pin velocity").

    Parameters
    ----------
    frames : array_like of shape (n_frames, N, 2)
        Pin centres (x, y) of consecutive camera frames, mm. NaN marks a pin not
        detected in a frame.

    Returns
    -------
    ndarray of shape (n_frames - 1, N, 2)
        ``frames[k + 1] - frames[k]``, mm per frame; NaN where the pin is missing
        in either frame. Velocity frame ``k`` belongs to the interval
        ``(t_k, t_{k+1}]``. A single frame gives an empty array.
    """
    arr = _pin_array(frames, "frames")
    if arr.ndim != 3:
        raise ValueError(f"frames must have shape (n_frames, N, 2); got {arr.shape}")
    if len(arr) == 0:
        raise ValueError("frames is empty; need at least one frame")
    return np.diff(arr, axis=0)


def circular_mean(
    angles: ArrayLike, axis: int | None = None, *, where: ArrayLike | None = None
) -> FloatArray:
    """Mean direction of angles, ``atan2(mean sin, mean cos)``, in rad.

    Parameters
    ----------
    angles : array_like
        Angles, rad. NaN entries are ignored.
    axis : int or None
        Axis to average over; None averages everything.
    where : array_like of bool, optional
        Entries to include (broadcast against ``angles``); the others are ignored.

    Returns
    -------
    ndarray
        Mean direction in ``[-pi, pi]`` rad, ``angles`` reduced along ``axis`` (a
        0-d array for ``axis=None``). Defined as 0 rad where no entry is included
        or where the resultant length ``|mean exp(i angle)|`` is below
        :data:`RESULTANT_EPS` (the angles cancel, so there is no mean direction).
    """
    a = np.asarray(angles, dtype=np.float64)
    keep = np.isfinite(a)
    if where is not None:
        keep &= np.broadcast_to(np.asarray(where, dtype=bool), a.shape)
    # Sums, not means: atan2 ignores the common 1 / count, and an empty slice
    # gives (0, 0) instead of a division by zero.
    s = np.sum(np.sin(a), axis=axis, where=keep)
    c = np.sum(np.cos(a), axis=axis, where=keep)
    count = np.sum(keep, axis=axis)
    resultant = np.hypot(s, c) / np.maximum(count, 1)
    mean = np.arctan2(s, c)
    return np.asarray(np.where(resultant > RESULTANT_EPS, mean, 0.0), dtype=np.float64)


def wrap_angle(angles: ArrayLike) -> FloatArray:
    """Wrap angles (rad) into ``(-pi, pi]``; -pi maps to +pi.

    Exact for inputs already in ``(-pi, pi]``, so wrapping twice changes nothing.
    """
    a = np.asarray(angles, dtype=np.float64)
    out = np.pi - np.mod(np.pi - a, 2.0 * np.pi)
    # np.mod of a tiny negative number can round to exactly 2 pi, giving -pi.
    return np.asarray(np.where(out <= -np.pi, out + 2.0 * np.pi, out))


def velocity_features(
    dxy: ArrayLike,
    variant: Variant = "dr_dtheta",
    shift_angles: bool = True,
    *,
    missing_count: bool = False,
) -> FloatArray:
    """The paper's per-frame feature vector from pin velocities.

    Parameters
    ----------
    dxy : array_like of shape (..., N, 2)
        Pin velocities (dx, dy), mm per frame (:func:`pin_velocities`); NaN marks
        a missing pin.
    variant : {"dr_dtheta", "dr", "dtheta"}
        Which features: both (2N: ``dr_0 .. dr_{N-1}`` then
        ``dtheta_0 .. dtheta_{N-1}``), magnitudes only (N) or angles only (N).
    shift_angles : bool
        Shift each frame's angles by their circular mean and wrap to
        ``(-pi, pi]`` (the paper's zero-mean angles); False keeps raw
        ``atan2(dy, dx)``.
    missing_count : bool
        Append the number of missing (NaN) pins in the frame as a last feature.

    Returns
    -------
    ndarray of shape (..., F)
        ``dr`` in mm/frame and ``dtheta`` in rad; finite everywhere (see the
        module docstring for missing and zero-velocity pins).
    """
    if variant not in VARIANTS:
        raise ValueError(f"variant must be one of {VARIANTS}; got {variant!r}")
    v = _pin_array(dxy, "dxy")
    dx, dy = v[..., 0], v[..., 1]
    missing = ~(np.isfinite(dx) & np.isfinite(dy))
    dx = np.where(missing, 0.0, dx)
    dy = np.where(missing, 0.0, dy)
    dr = np.hypot(dx, dy)
    parts: list[FloatArray] = []
    if variant in ("dr_dtheta", "dr"):
        parts.append(dr)
    if variant in ("dr_dtheta", "dtheta"):
        has_angle = dr > 0  # False for missing pins (set to 0 above) and still pins
        theta = np.arctan2(dy, dx)
        if shift_angles:
            mean = circular_mean(theta, axis=-1, where=has_angle)
            theta = wrap_angle(theta - mean[..., None])
        parts.append(np.where(has_angle, theta, 0.0))
    if missing_count:
        parts.append(np.sum(missing, axis=-1, keepdims=True, dtype=np.float64))
    return np.concatenate(parts, axis=-1)


def feature_names(
    n_pins: int, variant: Variant = "dr_dtheta", *, missing_count: bool = False
) -> tuple[str, ...]:
    """Column names matching :func:`velocity_features`: ``dr0..``, ``dtheta0..``, ``n_missing``."""
    if variant not in VARIANTS:
        raise ValueError(f"variant must be one of {VARIANTS}; got {variant!r}")
    if n_pins < 1:
        raise ValueError(f"n_pins must be >= 1; got {n_pins}")
    names: list[str] = []
    if variant in ("dr_dtheta", "dr"):
        names += [f"dr{i}" for i in range(n_pins)]
    if variant in ("dr_dtheta", "dtheta"):
        names += [f"dtheta{i}" for i in range(n_pins)]
    if missing_count:
        names.append("n_missing")
    return tuple(names)


def onset_velocity_index(times_s: ArrayLike, onset_s: float) -> int | None:
    """Index of the velocity frame whose interval ``(t_k, t_{k+1}]`` holds the onset.

    Parameters
    ----------
    times_s : array_like of shape (n_frames,)
        Camera frame times, s, increasing.
    onset_s : float
        Slip onset, s; NaN means the trial has no (recorded) slip.

    Returns
    -------
    int or None
        ``k`` with ``t_k < onset_s <= t_{k+1}``; 0 for an onset at or before the
        first frame (the first velocity frame already moves); None for a NaN onset
        or one after the last frame (no slip inside the recording).
    """
    t = np.asarray(times_s, dtype=np.float64)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError(f"times_s must be 1-D with >= 2 frames; got shape {t.shape}")
    if not np.isfinite(onset_s) or onset_s > t[-1]:
        return None
    return max(int(np.searchsorted(t, onset_s, side="left")) - 1, 0)


def frame_labels(
    n_frames: int, onset_frame: int | None, n_slip: int | None = 4
) -> NDArray[np.str_]:
    """'slip' / 'static' label of every velocity frame.

    Parameters
    ----------
    n_frames : int
        Number of velocity frames (camera frames - 1).
    onset_frame : int or None
        Onset velocity frame (:func:`onset_velocity_index`), or None for a trial
        without slip (every frame 'static').
    n_slip : int or None
        Velocity frames ``onset_frame .. onset_frame + n_slip - 1`` are 'slip'
        (the paper's best is 4); None marks every frame from the onset on.

    Returns
    -------
    ndarray of str, shape (n_frames,)
        :data:`SLIP` or :data:`STATIC`.
    """
    if n_frames < 0:
        raise ValueError(f"n_frames must be >= 0; got {n_frames}")
    if n_slip is not None and n_slip < 1:
        raise ValueError(f"n_slip must be >= 1 or None; got {n_slip}")
    labels = np.full(n_frames, STATIC, dtype="<U6")
    if onset_frame is None:
        return labels
    if onset_frame < 0:
        raise ValueError(f"onset_frame must be >= 0 or None; got {onset_frame}")
    stop = n_frames if n_slip is None else onset_frame + n_slip
    labels[onset_frame:stop] = SLIP
    return labels


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
