"""The ``contact_window`` preprocessing op: a pin field's window since contact, held per stream.

A GelSight contact detector (:class:`slipkit.families.gelsight.stream.PinContactDetector`)
is armed ``arm`` frames into the recording, measures positions in marker pitches (the
pitch of its first armed frame), reads the frames from the first armed one (the held
reference) until ``window`` armed frames have arrived, then the last ``window``, and
stops watching ``horizon`` frames after arming. A graph holds constants only, so the
frame counter, the pitch and the frames are kept here, in numpy, and the graph does the
pin-field math on a fixed-size window.

Input: one frame per call, ``(1, 2K)`` pin positions ``x_0..x_{K-1}, y_0..y_{K-1}``
(px), or ``(1, F * 2K)`` for ``fingertips`` = F fingertips side by side, each held on
its own (its own pitch and reference). Output ``(window + 1, F * 2K)`` float64, per
fingertip block:

* rows ``0 .. window - 1``: the window in pitches, oldest first, minus the mean pin
  position of its first frame (small numbers survive the graph's float32 input). A
  window of ``n < window`` armed frames is front-padded with copies of its first frame:
  a copy adds no displacement and no path, so the padded window gives the numbers of
  the ``n`` frames;
* row ``window``: ``[1, 0, ...]`` when the detector decides at this frame (armed, at
  least ``min_frames`` armed frames, inside the horizon, a finite pitch), else all 0
  (the graph then scores ``NO_SCORE``).

Parameters: ``arm`` (int >= 0), ``window`` (int >= 2), ``min_frames`` (int, 1 ..
``window``), ``horizon`` (int >= 1, optional: absent = the whole recording),
``fingertips`` (int 1 .. 8, optional: absent = 1). The state
depends on frames before the window (``stream_state``): the loop resets it where a new
recording starts.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slipkit.runtime._schema import MAX_FRAMES, Fields
from slipkit.runtime.preprocessing import Op, register_op

Array = NDArray[np.float64]

#: most frames one window may hold (2 s at 25 fps is 50)
MAX_WINDOW = 1000


def marker_pitch(frame: Array) -> float:
    """Median nearest-neighbour distance of one frame's finite pins (NaN below two).

    The runtime imports no family code, so this repeats
    :func:`slipkit.families.gelsight.features.pitch_of` on a ``2K`` row; a test keeps
    the two equal.
    """
    k = len(frame) // 2
    p = np.stack([frame[:k], frame[k:]], axis=1)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < 2:
        return math.nan
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


class _ContactWindow:
    """See the module docstring."""

    #: the counter, pitch and held reference come from the stream's start (see :class:`Op`)
    stream_state = True

    def __init__(
        self,
        arm: int,
        window: int,
        min_frames: int,
        horizon: int | None,
        channels: int,
        fingertips: int = 1,
    ) -> None:
        self.arm, self.window, self.min_frames = arm, window, min_frames
        self.horizon = horizon
        self.fingertips = fingertips
        self.k = channels // (2 * fingertips)
        self.out_shape: tuple[int, ...] = (window + 1, channels)
        self._out = np.zeros(self.out_shape)
        self._ring = np.zeros((window, channels))
        self.reset()

    def reset(self) -> None:
        """Forget the stream (a new recording starts with the next call)."""
        self._seen = 0
        self._armed = 0
        self.pitches = [math.nan] * self.fingertips

    def _deciding(self, t: int) -> bool:
        if t < self.arm:
            return False
        return self.horizon is None or t < self.arm + self.horizon

    def __call__(self, x: Array) -> Array:
        t = self._seen
        self._seen += 1
        out = self._out
        out.fill(0.0)
        if not self._deciding(t):
            return out
        frame = x[-1]
        k = self.k
        if self._armed == 0:
            self.pitches = [
                marker_pitch(frame[2 * k * b : 2 * k * (b + 1)])
                for b in range(self.fingertips)
            ]
        w = self.window
        self._ring[self._armed % w] = frame
        self._armed += 1
        if self._armed < self.min_frames:
            return out
        n = min(self._armed, w)
        order = (self._armed - n + np.arange(n)) % w
        for b, pitch in enumerate(self.pitches):
            if not pitch > 0:  # this fingertip cannot decide (too few pins)
                continue
            cols = slice(2 * k * b, 2 * k * (b + 1))
            body = out[:w, cols]
            body[w - n :] = self._ring[order, cols]
            body[: w - n] = body[w - n]
            ref = body[0]
            body[:, :k] -= np.nanmean(ref[:k])
            body[:, k:] -= np.nanmean(ref[k:])
            body /= pitch
            out[w, 2 * k * b] = 1.0
        return out


@register_op("contact_window")
def _contact_window(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "arm", "window", "min_frames", "horizon", "fingertips"))
    tips = (
        1
        if f.obj.get("fingertips") is None
        else f.integer("fingertips", minimum=1, maximum=8)
    )
    if (
        len(in_shape) != 2
        or in_shape[0] != 1
        or in_shape[1] % (2 * tips)
        or in_shape[1] < 6 * tips
    ):
        raise f.error(
            "op",
            f"needs one frame of {tips} x 2K pin positions (K >= 3), a window of "
            f"shape (1, {tips} * 2K); the step's input is {list(in_shape)}",
        )
    arm = f.integer("arm", minimum=0, maximum=MAX_FRAMES)
    window = f.integer("window", minimum=2, maximum=MAX_WINDOW)
    min_frames = f.integer("min_frames", minimum=1, maximum=window)
    horizon = (
        None
        if f.obj.get("horizon") is None
        else f.integer("horizon", minimum=1, maximum=MAX_FRAMES)
    )
    return _ContactWindow(arm, window, min_frames, horizon, int(in_shape[1]), tips)
