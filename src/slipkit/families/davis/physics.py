"""The DAVIS release's contact geometry (Rigi et al. 2018, Sec. 3 and 4.3): the patch an
object presses into the silicone (an ellipse growing with the force by Hertz's law, lost
from one side on release), the covered area over time and the paper's incipient-slip
onset from it. Pure numpy: the scene, its effects and the closed loop share it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ContactPatch:
    """The contact patch of one trial, in pixel coordinates.

    Pixel ``(x, y)`` has its centre at ``(x, y)``. The patch at time ``t`` is the set
    of points with ``ρ <= r(t)`` and ``q <= h(t)``, where ``ρ`` is the normalised
    elliptical radius (1 on the full-force ellipse), ``q`` the projection on the
    release direction, ``r(t)`` the press law and ``h(t)`` the receding edge.

    Attributes
    ----------
    cx, cy : float
        Centre, px.
    a, b : float
        Semi-axes at full force, px.
    angle : float
        Direction of the ``a`` axis, rad from +x.
    release_angle : float
        Side that loses contact first, rad from +x.
    press_start, press_s, release_start, release_s : float
        Phase start times and durations, s.
    """

    cx: float
    cy: float
    a: float
    b: float
    angle: float
    release_angle: float
    press_start: float
    press_s: float
    release_start: float
    release_s: float

    def normalised(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Coordinates along the two axes divided by the semi-axes (unit circle = full patch)."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        dx, dy = x - self.cx, y - self.cy
        return (c * dx + s * dy) / self.a, (-s * dx + c * dy) / self.b

    def radius(self, t: np.ndarray | float) -> np.ndarray:
        """Press law ``r(t) = ((t - t_press) / T_press)^(1/3)`` in [0, 1].

        Hertz: the contact radius grows as ``F^(1/3)`` while the force ramps linearly.
        """
        s = np.clip(
            (np.asarray(t, dtype=np.float64) - self.press_start) / self.press_s,
            0.0,
            1.0,
        )
        return np.cbrt(s)

    def q_max(self) -> float:
        """Largest projection of the full ellipse on the release direction, px."""
        c, s = (
            math.cos(self.release_angle - self.angle),
            math.sin(self.release_angle - self.angle),
        )
        return math.hypot(self.a * c, self.b * s)

    def projection(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Projection of each pixel centre on the release direction, px."""
        return (x - self.cx) * math.cos(self.release_angle) + (y - self.cy) * math.sin(
            self.release_angle
        )

    def cover_times(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """When the growing patch reaches each pixel (s): ``r(t) = ρ``; inf outside the patch."""
        u, v = self.normalised(x, y)
        rho = np.hypot(u, v)
        return np.where(rho <= 1.0, self.press_start + self.press_s * rho**3, np.inf)

    def uncover_times(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """When the receding edge ``h(t) = q_max (1 - 2 s)`` passes each covered pixel (s).

        The edge sweeps the release direction at constant speed, so contact is lost
        from one side first (incipient slip) until none is left.
        """
        qm = self.q_max()
        frac = np.clip((qm - self.projection(x, y)) / (2.0 * qm), 0.0, 1.0)
        u, v = self.normalised(x, y)
        inside = np.hypot(u, v) <= 1.0
        return np.where(inside, self.release_start + self.release_s * frac, np.inf)

    def bbox(
        self, scale: float, margin: float, width: int, height: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates of the patch's bounding box grown by ``scale`` and ``margin`` px."""
        half = scale * max(self.a, self.b) + margin
        x0, x1 = (
            max(0, math.floor(self.cx - half)),
            min(width - 1, math.ceil(self.cx + half)),
        )
        y0, y1 = (
            max(0, math.floor(self.cy - half)),
            min(height - 1, math.ceil(self.cy + half)),
        )
        gx, gy = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
        return gx.ravel(), gy.ravel()


def area_curve(t: np.ndarray, t_cover: np.ndarray, t_uncover: np.ndarray) -> np.ndarray:
    """Covered pixels at each time: ``#(t_cover <= t) - #(t_uncover <= t)``."""
    covered = np.searchsorted(np.sort(t_cover), t, side="right")
    lost = np.searchsorted(np.sort(t_uncover), t, side="right")
    return (covered - lost).astype(np.int64)


def incipient_slip_onset(
    t: np.ndarray, area: np.ndarray, hold: tuple[float, float]
) -> float:
    """Paper, Sec. 4.3: the first frame after the hold phase whose area is below the
    minimum area seen during the hold (constant force) phase; NaN if none."""
    in_hold = (t >= hold[0]) & (t < hold[1])
    if not in_hold.any():
        return math.nan
    below = np.flatnonzero((t >= hold[1]) & (area < area[in_hold].min()))
    return float(t[below[0]]) if len(below) else math.nan
