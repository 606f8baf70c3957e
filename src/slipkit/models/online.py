"""Online slip declaration from per-frame decisions (numpy only, runtime-safe).

The TacTip paper (James, Pestell, Lepora 2018, Sec. IV-C) reacts only after two
consecutive velocity frames are classified 'slip', to suppress single-frame
false positives. :func:`debounce` is that rule for any ``k``;
:func:`detection_delay` measures when it first fires relative to the onset.

Frame indices are velocity frames (see :mod:`slipkit.features.pins`): index
``k`` is available at camera frame ``k + 1``. Scikit-learn has no streaming
decision rule, so these few lines are written here.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slipkit.features.pins import SLIP


def _as_slip(decisions: ArrayLike, positive: object) -> NDArray[np.bool_]:
    """Booleans as they are; anything else compared with the ``positive`` label."""
    arr = np.asarray(decisions)
    if arr.ndim != 1:
        raise ValueError(
            f"decisions must be 1-D (one per frame); got shape {arr.shape}"
        )
    return arr if arr.dtype == np.bool_ else np.asarray(arr == positive, dtype=bool)


def _check_k(k: int) -> int:
    if int(k) != k or k < 1:
        raise ValueError(f"k must be an integer >= 1 (frames); got {k!r}")
    return int(k)


def debounce(
    decisions: ArrayLike, k: int = 2, *, positive: object = SLIP
) -> NDArray[np.bool_]:
    """Slip declared on frames that end a run of ``k`` consecutive slip decisions.

    Parameters
    ----------
    decisions : array_like of shape (n_frames,)
        Per-frame decisions: booleans (True = slip) or labels, where
        ``positive`` marks slip (default ``'slip'``).
    k : int
        Consecutive slip frames needed (the paper: 2); ``k=1`` returns the
        decisions unchanged.
    positive : object
        The slip label when ``decisions`` are not booleans.

    Returns
    -------
    ndarray of bool, shape (n_frames,)
        ``out[i]`` is True when frames ``i - k + 1 .. i`` are all slip (never in
        the first ``k - 1`` frames), i.e. the rule has fired by frame ``i``.
    """
    k = _check_k(k)
    slip = _as_slip(decisions, positive)
    # Length of the run of slip frames ending at each frame: a running count
    # reset to 0 at every non-slip frame.
    idx = np.arange(len(slip))
    last_reset = np.maximum.accumulate(np.where(slip, -1, idx))
    run = idx - last_reset
    return np.asarray(run >= k)


def first_detection(
    decisions: ArrayLike, k: int = 2, *, positive: object = SLIP
) -> int | None:
    """Velocity frame at which the debounced rule first fires, None if it never does."""
    fired = np.flatnonzero(debounce(decisions, k, positive=positive))
    return int(fired[0]) if len(fired) else None


def detection_delay(
    pred: ArrayLike, onset_index: int, k: int = 2, *, positive: object = SLIP
) -> int | None:
    """Frames from the onset to the first firing of the ``k``-frame rule.

    Parameters
    ----------
    pred : array_like of shape (n_frames,)
        Per-velocity-frame decisions (booleans or labels, see :func:`debounce`).
    onset_index : int
        Onset velocity frame (:func:`slipkit.features.onset_velocity_index`).
    k : int
        Consecutive slip frames needed.
    positive : object
        The slip label when ``pred`` holds labels.

    Returns
    -------
    int or None
        ``first_detection - onset_index``, frames. A perfect classifier gives
        ``k - 1`` (the rule needs the onset frame and ``k - 1`` more). Negative:
        a false alarm before the onset, which in the online loop is the reaction
        that happens. None: the rule never fires (a missed slip).
    """
    if int(onset_index) != onset_index or onset_index < 0:
        raise ValueError(f"onset_index must be an integer >= 0; got {onset_index!r}")
    first = first_detection(pred, k, positive=positive)
    return None if first is None else first - int(onset_index)


def frames_to_ms(frames: ArrayLike, rate_hz: float) -> NDArray[np.float64]:
    """Frame counts to milliseconds at a frame rate (Hz): ``1000 frames / rate``."""
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a finite number > 0; got {rate_hz!r}")
    return np.asarray(frames, dtype=np.float64) * (1000.0 / rate_hz)
