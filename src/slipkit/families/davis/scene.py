"""DAVIS release (Rigi et al. 2018, Sensors 18(2):333, Sec. 3 and 4.3).

An event camera (190 x 180 pixels) watches, through transparent silicone, the
contact patch of an object that a robot presses (force ramps up), holds (constant
force) and releases. The backbone is the patch itself: an ellipse whose size
follows the force while pressed and which loses contact from one side during the
release, plus the ground-truth contact area a 1000 FPS camera would see
(``truth_contact``) and the incipient-slip onset derived from it as in the paper.

Events are effects (``slipkit.families.davis.effects``): contact-change events at the
patch edge, vibration incidents, background noise. The backbone only stores, per
pixel, when the edge covers and uncovers it. See ``docs/families/davis.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import LabelSpec, StreamSpec
from slipkit.families.davis.physics import (
    ContactPatch,
    area_curve,
    incipient_slip_onset,
)
from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, sample_times

EVENT_CHANNELS = ("x", "y", "polarity")
EVENT_UNITS = {"x": "px", "y": "px", "polarity": "1"}
TRUTH_CHANNELS = ("area_px", "area_mm2")
TRUTH_UNITS = {"area_px": "px", "area_mm2": "mm^2"}


def _range(key: str, value: Any) -> tuple[float, float]:
    """A config range: a number (fixed) or ``[lo, hi]``, both > 0; raises naming ``key``."""
    return params.value_range(f"model.{key}", value, lo=0.0, strict_lo=True)


def _positive(key: str, value: float, *, allow_zero: bool = False) -> float:
    return params.number(f"model.{key}", value, lo=0.0, strict_lo=not allow_zero)


class DavisRelease:
    """Scene ``davis_release``: press, hold and release an object on silicone under a DAVIS.

    Parameters (keyword-only, the keys of ``configs/scene/davis_release.yaml``)
    ----------
    width_px, height_px : int
        Event array size (paper: 190 x 180).
    pixel_mm : float
        Side of one pixel on the silicone surface, mm (paper: 0.126 mm).
    truth_rate_hz : float
        Frame rate of the ground-truth contact-area camera, Hz (paper: 1000 FPS).
    timestamp_resolution_s : float
        Event clock resolution, s (paper: up to 1 µs).
    pre_s, post_s : float
        Time without contact before the press and after the release, s.
    press_s, hold_s, release_s : float or [lo, hi]
        Phase durations, s (uniform).
    objects : mapping of str to [a_mm, b_mm]
        Contact-patch semi-axes at full force per object, mm; one object per trial.
    centre_jitter_px : float
        The patch centre is drawn uniformly within this many px of the array centre (each axis).
    """

    sensor = "davis"
    groups: tuple[str, ...] = ("object",)

    def __init__(
        self,
        *,
        width_px: int = 190,
        height_px: int = 180,
        pixel_mm: float = 0.126,
        truth_rate_hz: float = 1000.0,
        timestamp_resolution_s: float = 1e-6,
        pre_s: float = 0.1,
        press_s: Any = (0.3, 0.6),
        hold_s: Any = (0.5, 1.0),
        release_s: Any = (0.3, 0.6),
        post_s: float = 0.1,
        objects: Mapping[str, Sequence[float]] | None = None,
        centre_jitter_px: float = 15.0,
    ) -> None:
        for key, val in (("width_px", width_px), ("height_px", height_px)):
            if int(val) != val or val < 1:
                raise SimulationError(
                    f"model.{key}: must be an integer >= 1; got {val!r}"
                )
        self.width_px, self.height_px = int(width_px), int(height_px)
        self.pixel_mm = _positive("pixel_mm", pixel_mm)
        self.truth_rate_hz = _positive("truth_rate_hz", truth_rate_hz)
        self.timestamp_resolution_s = _positive(
            "timestamp_resolution_s", timestamp_resolution_s, allow_zero=True
        )
        self.pre_s = _positive("pre_s", pre_s, allow_zero=True)
        self.press_s = _range("press_s", press_s)
        self.hold_s = _range("hold_s", hold_s)
        self.release_s = _range("release_s", release_s)
        self.post_s = _positive("post_s", post_s, allow_zero=True)
        if objects is None:
            objects = {
                "disc_r3mm": (3.0, 3.0),
                "disc_r5mm": (5.0, 5.0),
                "ellipse_5x3mm": (5.0, 3.0),
            }
        if not objects:
            raise SimulationError(
                "model.objects: list at least one object: {name: [a_mm, b_mm]}"
            )
        self.objects: dict[str, tuple[float, float]] = {}
        for name, axes in objects.items():
            if not (
                isinstance(axes, Sequence)
                and not isinstance(axes, str)
                and len(axes) == 2
            ):
                raise SimulationError(
                    f"model.objects.{name}: expected [a_mm, b_mm]; got {axes!r}"
                )
            a_mm, b_mm = float(axes[0]), float(axes[1])
            if not (
                math.isfinite(a_mm) and math.isfinite(b_mm) and a_mm > 0 and b_mm > 0
            ):
                raise SimulationError(
                    f"model.objects.{name}: semi-axes must be finite and > 0 mm; got {axes!r}"
                )
            self.objects[str(name)] = (a_mm, b_mm)
        self.centre_jitter_px = _positive(
            "centre_jitter_px", centre_jitter_px, allow_zero=True
        )
        largest = max(max(ax) for ax in self.objects.values()) / self.pixel_mm
        room = min(self.width_px, self.height_px) / 2.0 - self.centre_jitter_px
        if largest > room:
            raise SimulationError(
                f"model.objects: a patch of {largest:.0f} px semi-axis does not fit the "
                f"{self.width_px} x {self.height_px} array with centre_jitter_px={self.centre_jitter_px}"
            )

    def streams(self) -> dict[str, StreamSpec]:
        """``events`` (x, y, polarity; asynchronous) and ``truth_contact`` (area at the truth rate)."""
        return {
            "events": StreamSpec(
                "events",
                EVENT_CHANNELS,
                EVENT_UNITS,
                rate_hz=None,
                kind="events",
                description="DVS events sorted by t: pixel x, y and polarity (+1 brighter / contact lost, -1 darker / contact gained)",
            ),
            "truth_contact": StreamSpec(
                "truth_contact",
                TRUTH_CHANNELS,
                TRUTH_UNITS,
                rate_hz=self.truth_rate_hz,
                description="ground-truth contact area seen by the high-speed camera",
            ),
        }

    def labels(self) -> dict[str, LabelSpec]:
        """``slip_onset_s``: incipient slip, from the contact-area curve (paper Sec. 4.3)."""
        return {"slip_onset_s": LabelSpec("slip_onset_s", unit="s")}

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """Draw the object, phase durations, patch orientation, release side and centre."""
        names = list(self.objects)
        obj = names[int(rng.integers(len(names)))]
        return {
            "object": obj,
            "press_s": float(rng.uniform(*self.press_s)),
            "hold_s": float(rng.uniform(*self.hold_s)),
            "release_s": float(rng.uniform(*self.release_s)),
            "angle": float(rng.uniform(0.0, math.pi)),
            "release_angle": float(rng.uniform(0.0, 2.0 * math.pi)),
            "centre_offset_px": rng.uniform(
                -self.centre_jitter_px, self.centre_jitter_px, size=2
            ),
        }

    def patch(self, params: Mapping[str, Any]) -> ContactPatch:
        """The trial's contact patch from its drawn parameters."""
        a_mm, b_mm = self.objects[str(params["object"])]
        press_start = self.pre_s
        release_start = press_start + float(params["press_s"]) + float(params["hold_s"])
        off = np.asarray(params["centre_offset_px"], dtype=np.float64)
        return ContactPatch(
            cx=(self.width_px - 1) / 2.0 + float(off[0]),
            cy=(self.height_px - 1) / 2.0 + float(off[1]),
            a=a_mm / self.pixel_mm,
            b=b_mm / self.pixel_mm,
            angle=float(params["angle"]),
            release_angle=float(params["release_angle"]),
            press_start=press_start,
            press_s=float(params["press_s"]),
            release_start=release_start,
            release_s=float(params["release_s"]),
        )

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        """Per-pixel cover/uncover times of the patch, the truth area curve and the onset; no events."""
        del rng  # deterministic given the drawn parameters
        patch = self.patch(params)
        duration = patch.release_start + patch.release_s + self.post_s
        x, y = patch.bbox(1.0, 1.0, self.width_px, self.height_px)
        t_cover = patch.cover_times(x, y)
        inside = np.isfinite(t_cover)
        x, y, t_cover = x[inside], y[inside], t_cover[inside]
        t_uncover = patch.uncover_times(x, y)
        t_truth = sample_times(duration, self.truth_rate_hz)
        area = area_curve(t_truth, t_cover, t_uncover)
        hold = (patch.press_start + patch.press_s, patch.release_start)
        onset = incipient_slip_onset(t_truth, area, hold)
        truth = np.column_stack([area, area * self.pixel_mm**2])
        return SceneState(
            time={"events": np.zeros(0), "truth_contact": t_truth},
            signals={
                "events": np.zeros((0, 3), dtype=np.int64),
                "truth_contact": truth,
                "pixels": np.column_stack([x, y]).astype(np.int64),
                "t_cover": t_cover,
                "t_uncover": t_uncover,
            },
            truth={
                "slip_onset_s": onset,
                "patch": patch,
                "duration_s": duration,
                "sensor_shape": (self.width_px, self.height_px),
                "object": str(params["object"]),
            },
        )

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        """Events as ``t, x, y, polarity`` (t on the event clock); truth area; onset; object."""
        t = np.asarray(state.time["events"], dtype=np.float64)
        ev = np.asarray(state.signals["events"]).reshape(-1, 3)
        if self.timestamp_resolution_s > 0:
            t = np.round(t / self.timestamp_resolution_s) * self.timestamp_resolution_s
        order = np.argsort(t, kind="stable")
        events = pd.DataFrame(
            {
                "t": t[order],
                "x": ev[order, 0].astype(np.int16),
                "y": ev[order, 1].astype(np.int16),
                "polarity": ev[order, 2].astype(np.int8),
            }
        )
        truth = pd.DataFrame(
            np.column_stack(
                [state.time["truth_contact"], state.signals["truth_contact"]]
            ),
            columns=["t", *TRUTH_CHANNELS],
        )
        labels = {"slip_onset_s": float(state.truth["slip_onset_s"])}
        return (
            {"events": events, "truth_contact": truth},
            labels,
            {"object": str(state.truth["object"])},
        )
