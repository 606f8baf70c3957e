"""Sliding windows of consecutive frames, flattened for window classifiers (numpy only).

Su et al. 2015 (Sec. IV-C) classify slip from "100 consecutive timestamps of
19-dimensional electrode values", one 1900-long input vector. A window here is
``W`` consecutive frames of ``C`` channels, flattened time-major: the first ``C``
values are the window's first frame, the last ``C`` its last frame (``X.reshape(-1,
W, C)`` recovers the frames). Windows start every ``hop`` frames; each is known by the
index (and so the time) of its **last** frame, the moment a classifier running
online could first output it.

Modes (what a window holds):

``"raw"``
    The frames as recorded.
``"window"``
    Dynamics only, local: every frame minus the window's own first frame (the first
    ``C`` values are zero). Offsets that stay constant within the window are gone.
``"trial"``
    Dynamics only, since contact: every frame minus ``origin`` (default: the trial's
    first frame, ``frames[0]``). The BioTacSP-DoS README's "each sequence's first
    frame subtracted".
``"first_frame"``
    Control without any dynamics: ``origin`` (default ``frames[0]``) repeated for
    all ``W`` frames, so every window of a trial is the same vector, of the same
    length as a raw window (the same model can be fitted on it).

This module imports numpy only: the gripper-PC runtime keeps the last ``W`` frames
in a buffer and calls :func:`sliding_windows` on them (one window, ``hop`` ignored).
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, DTypeLike, NDArray

__all__ = [
    "MODES",
    "NAN_POLICIES",
    "Mode",
    "NanPolicy",
    "Windows",
    "frames_for_ms",
    "n_windows",
    "sliding_windows",
    "window_end_index",
]

Mode = Literal["raw", "window", "trial", "first_frame"]
NanPolicy = Literal["raise", "omit", "propagate"]
MODES: tuple[str, ...] = ("raw", "window", "trial", "first_frame")
NAN_POLICIES: tuple[str, ...] = ("raise", "omit", "propagate")


class Windows(NamedTuple):
    """Flattened windows and the frame each one ends on.

    Attributes
    ----------
    X : ndarray of shape (n_windows, width * n_channels)
        Window features, time-major (``X.reshape(-1, width, n_channels)``).
    end : ndarray of int64, shape (n_windows,)
        Index (into ``frames``) of each window's last frame; ``t[end]`` is its time.
    """

    X: NDArray[np.floating]
    end: NDArray[np.int64]


def _check_positive_int(name: str, value: int) -> int:
    if isinstance(value, bool) or int(value) != value or int(value) < 1:
        raise ValueError(f"{name} must be an integer >= 1 frame; got {value!r}")
    return int(value)


def n_windows(n_frames: int, width: int, hop: int = 1) -> int:
    """How many whole windows of ``width`` frames, ``hop`` apart, fit in ``n_frames``.

    ``max(0, (n_frames - width) // hop + 1)``: zero when the trial is shorter than a
    window (no partial windows are made).
    """
    width = _check_positive_int("width", width)
    hop = _check_positive_int("hop", hop)
    if n_frames < width:
        return 0
    return (int(n_frames) - width) // hop + 1


def window_end_index(n_frames: int, width: int, hop: int = 1) -> NDArray[np.int64]:
    """Index of the last frame of each window: ``width - 1, width - 1 + hop, ...``."""
    n = n_windows(n_frames, width, hop)
    return (width - 1 + hop * np.arange(n)).astype(np.int64)


def frames_for_ms(ms: float, rate_hz: float) -> int:
    """Whole frames in ``ms`` milliseconds at ``rate_hz`` Hz (rounded, at least 1).

    50 ms at 100 Hz is 5 frames; 333.3 ms at 300 Hz is 100 frames.
    """
    if not (np.isfinite(ms) and ms > 0):
        raise ValueError(f"window length must be > 0 ms; got {ms!r}")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"frame rate must be > 0 Hz; got {rate_hz!r}")
    return max(1, round(ms * rate_hz / 1000.0))


def sliding_windows(
    frames: ArrayLike,
    width: int,
    *,
    hop: int = 1,
    mode: Mode = "raw",
    origin: ArrayLike | None = None,
    nan_policy: NanPolicy = "raise",
    dtype: DTypeLike = np.float32,
) -> Windows:
    """Flattened windows of ``width`` consecutive frames, one every ``hop`` frames.

    Parameters
    ----------
    frames : array_like of shape (n_frames, n_channels)
        One trial's frames in time order (e.g. electrode counts at 300 Hz).
    width : int >= 1
        Frames per window, W (the paper: 100 frames = 333 ms at 300 Hz).
    hop : int >= 1
        Frames between the starts of consecutive windows.
    mode : {"raw", "window", "trial", "first_frame"}
        What a window holds (see the module docstring).
    origin : array_like of shape (n_channels,), optional
        The frame ``"trial"`` subtracts and ``"first_frame"`` repeats; default
        ``frames[0]``. The runtime passes the frame it stored at contact.
    nan_policy : {"raise", "omit", "propagate"}
        Non-finite frames (dropped samples): ``"raise"`` a ValueError naming the
        first bad frame; ``"omit"`` every window that holds a non-finite value (for
        ``"trial"`` and ``"first_frame"`` a non-finite ``origin`` omits them all);
        ``"propagate"`` keep them as they are.
    dtype : dtype
        Floating type of ``X`` (float32: what the torch models take).

    Returns
    -------
    Windows
        ``X`` of shape (n_windows, width * n_channels) and ``end``, the index of
        each window's last frame. A trial shorter than ``width`` frames gives
        ``n_windows == 0`` (empty arrays of the right shape), not an error: a
        dataset may hold a few short trials.

    Raises
    ------
    ValueError
        ``frames`` not 2-D, ``width`` or ``hop`` not a positive integer, an unknown
        ``mode`` or ``nan_policy``, ``origin`` of the wrong length, or a non-finite
        value under ``nan_policy="raise"``.
    """
    x = np.asarray(frames, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(
            f"frames must be 2-D (n_frames, n_channels); got shape {x.shape}"
        )
    width = _check_positive_int("width", width)
    hop = _check_positive_int("hop", hop)
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}; got {mode!r}")
    if nan_policy not in NAN_POLICIES:
        raise ValueError(
            f"nan_policy must be one of {NAN_POLICIES}; got {nan_policy!r}"
        )
    n_frames, n_channels = x.shape
    end = window_end_index(n_frames, width, hop)
    if len(end) == 0:
        # Shorter than one window (or empty): nothing to check or subtract.
        return Windows(np.empty((0, width * n_channels), dtype=dtype), end)
    ref: NDArray[np.float64] | None = None
    if mode in ("trial", "first_frame"):
        ref = x[0] if origin is None else np.asarray(origin, dtype=np.float64)
        if ref.shape != (n_channels,):
            raise ValueError(
                f"origin must hold one value per channel ({n_channels}); got shape "
                f"{ref.shape}"
            )
    if nan_policy == "raise":
        bad = ~np.isfinite(x).all(axis=1)
        if bad.any():
            raise ValueError(
                f"frame {int(np.flatnonzero(bad)[0])} holds a non-finite value "
                "(nan_policy='raise'; use 'omit' to drop the windows holding it)"
            )
        if ref is not None and not np.isfinite(ref).all():
            raise ValueError(f"origin holds a non-finite value ({mode=!r})")
    # sliding_window_view is a strided view (no copy): shape (n, C, W) with the
    # window axis last; transpose to (n, W, C) so flattening is time-major.
    view = sliding_window_view(x, width, axis=0)[::hop].transpose(0, 2, 1)
    if mode == "raw":
        win = view
    elif mode == "window":
        win = view - view[:, :1, :]
    elif mode == "trial":
        assert ref is not None
        win = view - ref
    else:
        assert ref is not None
        win = np.broadcast_to(ref, view.shape)
    out = np.ascontiguousarray(win, dtype=dtype).reshape(len(end), width * n_channels)
    if nan_policy == "omit":
        keep = np.isfinite(out).all(axis=1)
        out, end = out[keep], end[keep]
    return Windows(out, end)
