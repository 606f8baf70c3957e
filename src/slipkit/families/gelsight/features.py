"""Pin-motion features of a GelSight marker field, numpy only (runs on the gripper PC too).

Positions are in marker pitches (px divided by the first frame's pitch), so sensors
that image the gel at different scales give the same numbers. Over a window of frames
(the last ``window`` frames up to frame ``t``) the displacement field ``d_i = p_i(t) -
p_i(t0)`` is fitted by least squares with an affine map ``d = A (p - mean p) + b``:

* ``translation`` -- ``|b|``, the net (steady) displacement of the field;
* ``divergence`` -- ``A00 + A11`` (the gel spreading or contracting: normal load);
* ``curl`` -- ``A10 - A01`` (rotation);
* ``shear`` -- the traceless symmetric part's magnitude;
* ``residual`` -- RMS of the field left after the affine fit (non-rigid motion: part
  of the contact sliding while the rest sticks);
* ``path`` -- the field's mean path length over the window (sum of frame-to-frame
  mean displacements), and ``straightness`` = ``translation / path`` (1: steady drift,
  0: a shake that returns);
* ``speed`` -- the largest frame-to-frame mean pin speed in the window.

A pin the first frame lacked (NaN) is left out of every fit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

FEATURES: tuple[str, ...] = (
    "translation",
    "divergence",
    "curl",
    "shear",
    "residual",
    "path",
    "straightness",
    "speed",
)


def to_points(frames: FloatArray) -> FloatArray:
    """``(n, 2K)`` rows ``x_0..x_{K-1}, y_0..y_{K-1}`` as ``(n, K, 2)`` points."""
    frames = np.asarray(frames, dtype=np.float64)
    k = frames.shape[1] // 2
    return np.stack([frames[:, :k], frames[:, k:]], axis=-1)


def pitch_of(points: FloatArray) -> float:
    """Median nearest-neighbour distance of one frame's pins (the marker pitch)."""
    p = points[np.isfinite(points).all(axis=1)]
    if len(p) < 2:
        return float("nan")
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


def affine_fit(
    ref: FloatArray, disp: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """Least-squares ``disp = A (ref - mean) + b`` over the finite pins: A, b, RMS residual."""
    ok = np.isfinite(ref).all(axis=1) & np.isfinite(disp).all(axis=1)
    r, d = ref[ok], disp[ok]
    if len(r) < 3:
        return np.zeros((2, 2)), np.zeros(2), 0.0
    c = r - r.mean(axis=0)
    design = np.column_stack([c, np.ones(len(c))])
    coef, *_ = np.linalg.lstsq(design, d, rcond=None)
    resid = d - design @ coef
    return coef[:2].T, coef[2], float(np.sqrt(np.mean(np.sum(resid**2, axis=1))))


def window_features(points: FloatArray) -> FloatArray:
    """The :data:`FEATURES` of one window of pin positions ``(n, K, 2)`` (pitches)."""
    if len(points) < 2:
        return np.zeros(len(FEATURES))
    a, b, resid = affine_fit(points[0], points[-1] - points[0])
    step = np.diff(points, axis=0)
    mean_step = np.nanmean(step, axis=1)  # (n-1, 2)
    speeds = np.linalg.norm(mean_step, axis=1)
    path = float(np.sum(speeds))
    translation = float(np.linalg.norm(b))
    shear = float(np.hypot(a[0, 0] - a[1, 1], a[0, 1] + a[1, 0]))
    return np.array(
        [
            translation,
            a[0, 0] + a[1, 1],
            a[1, 0] - a[0, 1],
            shear,
            resid,
            path,
            translation / path if path > 1e-9 else 0.0,
            float(np.max(speeds)),
        ]
    )


def trial_features(
    frames: FloatArray, *, window: int, arm: int = 0, min_frames: int = 5
) -> FloatArray:
    """Features at every frame of one recording ``(n, 2K)`` (px): ``(n, F)``.

    Frames before ``arm`` are ignored (the detector is not armed yet); frame ``t`` reads
    the frames ``max(arm, t - window + 1) .. t``; a frame with fewer than
    ``min_frames`` armed frames behind it is NaN. Positions are divided by the pitch of
    the first armed frame.
    """
    pts = to_points(frames)
    out = np.full((len(pts), len(FEATURES)), np.nan)
    if len(pts) <= arm:
        return out
    pitch = pitch_of(pts[arm])
    if not np.isfinite(pitch) or pitch <= 0:
        return out
    pts = pts / pitch
    for t in range(arm + min_frames - 1, len(pts)):
        out[t] = window_features(pts[max(arm, t - window + 1) : t + 1])
    return out


class FeatureStream:
    """:func:`trial_features` one frame at a time (the deployed form)."""

    def __init__(self, *, window: int, arm: int = 0, min_frames: int = 5) -> None:
        self.window, self.arm, self.min_frames = int(window), int(arm), int(min_frames)
        self.reset()

    def reset(self) -> None:
        self._seen = 0
        self._pitch = float("nan")
        self._buf: list[FloatArray] = []

    def update(self, frame: FloatArray) -> FloatArray | None:
        """Features after this frame (``2K`` px values), or None while warming up."""
        self._seen += 1
        if self._seen <= self.arm:
            return None
        pts = to_points(np.asarray(frame, dtype=np.float64)[None, :])[0]
        if self._seen == self.arm + 1:  # the first armed frame sets the pitch
            self._pitch = pitch_of(pts)
        if not self._pitch > 0:  # no pitch at the first armed frame: never a feature
            return None
        self._buf.append(pts / self._pitch)
        if len(self._buf) > self.window:
            self._buf.pop(0)
        if len(self._buf) < self.min_frames:
            return None
        return window_features(np.stack(self._buf))


__all__ = [
    "FEATURES",
    "FeatureStream",
    "affine_fit",
    "pitch_of",
    "to_points",
    "trial_features",
    "window_features",
]
