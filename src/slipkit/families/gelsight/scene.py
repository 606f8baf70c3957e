"""GelSight grasp scene: an object held between two gel fingertips either slips out or is
only wiggled (``configs/scene/gelsight_grasp.yaml``; ``docs/families/gelsight.md``).

The scene model holds the trial's kinematics and the gels' marker grids at rest; the
effects (:mod:`slipkit.families.gelsight.effects`) add what the scene config names:

* ``shake`` -- disturbances: bursts of oscillating tangential drag and twist on the held
  object (the wiggle), without slip;
* ``gel_shear`` -- the marker field: the gel spreads under the normal load and is
  sheared by the drag; when the object slides, the contact patch moves with it, and as
  it leaves, the load falls to zero and the gel returns to rest;
* ``marker_grid`` -- grey camera frames with a dark dot per marker;
* ``blur`` and ``lighting_drift`` -- image effects on those frames.

When the frames exist, :meth:`GelSightGrasp.render` tracks them with the family's own
tracker (:func:`slipkit.families.gelsight.tracking.track_frames`, the importer's), so the
image effects act on the pins the way they do in real videos (lost or jittered markers).
Without ``marker_grid`` the streams hold the true positions of the same pins. The output
is the importer's format: streams ``camera_0`` and ``camera_2`` of ``n_pins`` tracked
pins (``x_i``, ``y_i`` in px) at 25 fps, the label ``slipped`` and the group ``object``.
Every trial has the same length, so the clip length says nothing about the label.

Units: the kinematics are in marker pitches (world frame: x right, y down as seen by
``camera_0``); ``camera_2`` faces it from the other side of the object and sees x mirrored.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import LabelSpec, StreamSpec
from slipkit.families.gelsight.importer import (
    CAMERAS,
    FINGERTIPS,
    fingertips_frame,
    fingertips_spec,
    pin_channels,
)
from slipkit.families.gelsight.tracking import track_frames
from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, sample_times

Range = tuple[float, float]

#: per-object properties and their ranges (drawn once per object, fixed across runs)
OBJECT_KEYS = ("contact_radius", "drag", "kinetic_ratio", "spread")


def _range(value: Any, key: str, lo: float = 0.0, strict: bool = True) -> Range:
    return params.value_range(key, value, lo=lo, strict_lo=strict)


def _scalar(value: Any, key: str, lo: float = 0.0, strict: bool = True) -> float:
    return params.single(key, value, lo=lo, strict_lo=strict)


def _draw(rng: np.random.Generator, r: Range) -> float:
    return float(params.draw(rng, r))


def rest_grid(
    width: int, height: int, pitch: float, angle_rad: float, offset: np.ndarray
) -> np.ndarray:
    """Marker centres (m, 2; px) of a square grid covering the frame and one pitch
    beyond it, rotated by ``angle_rad`` about the frame centre and shifted by
    ``offset`` px."""
    centre = np.array([width / 2.0, height / 2.0])
    half = 0.5 * np.hypot(width, height) / pitch + 1.0
    k = np.arange(-np.ceil(half), np.ceil(half) + 1)
    gx, gy = np.meshgrid(k, k)
    q = np.column_stack([gx.ravel(), gy.ravel()]) * pitch
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    p = q @ np.array([[c, s], [-s, c]]) + centre + offset
    keep = (
        (p[:, 0] > -pitch)
        & (p[:, 0] < width + pitch)
        & (p[:, 1] > -pitch)
        & (p[:, 1] < height + pitch)
    )
    return p[keep]


class GelSightGrasp:
    """An object held between two GelSight fingertips slips out, or is only wiggled.

    Phases of a slip trial: held (``0 .. onset``), sliding at ``slide_speed`` for
    ``slide_s`` (the contact patch moves along with the object, and the drag falls to
    its kinetic share), then leaving: the normal load falls to zero over ``release_s``
    and the gel returns to rest. A wiggle trial is held throughout; with
    ``set_down_fraction`` > 0 that share of wiggle trials end with the object set down
    (the load falls to zero without a slide). Wiggles themselves are the ``shake``
    effect, which acts on every trial.

    Parameters
    ----------
    rate_hz : float
        Frame rate (Hz); the real fingertips run at 25 fps.
    duration_s : float
        Length of every trial (s).
    slip_fraction : float
        Share of trials that slip.
    onset_s : [low, high]
        When the object starts to slide (s), drawn per slip trial.
    slide_s : [low, high]
        How long it slides before it leaves (s).
    slide_speed : [low, high]
        Slide speed, marker pitches per second.
    slide_direction_deg : [low, high]
        Slide direction in ``camera_0``'s image (90: down, with gravity).
    release_s : [low, high]
        How long the load takes to fall to zero as the object leaves (s).
    set_down_fraction : float
        Share of wiggle trials that end with the object set down.
    set_down_s : [low, high]
        When a set-down starts (s).
    objects : int
        Number of objects (the group); a trial draws one.
    object_seed : int
        Seeds the objects' properties, so they are the same in every run.
    contact_radius, drag, kinetic_ratio, spread : [low, high]
        Ranges of the per-object properties: the contact patch's radius (pitches); the
        static tangential drag of the held object's weight on the gel (pitches); the
        kinetic share of that drag while sliding; and the gel's spreading under the
        normal load (pitches of displacement per pitch from the contact centre).
    width_px, height_px : int
        Camera frame size (px).
    pitch_px : [low, high]
        Marker pitch in the image (px), drawn per fingertip.
    grid_angle_deg : [low, high]
        Rotation of the marker grid in the image.
    layout_jitter : float
        Irregularity of the printed grid, pitches (s.d.).
    contact_offset : float
        Largest distance of the contact centre from the image centre, pitches.
    n_pins : int
        Pins per fingertip (the importer's 30 nearest the image centre).
    snap : float
        The tracker's snap distance, pitches (the importer's 0.35).
    """

    sensor = "gelsight"
    groups: tuple[str, ...] = ("object",)

    def __init__(
        self,
        *,
        rate_hz: float = 25.0,
        duration_s: float = 8.0,
        slip_fraction: float = 0.45,
        onset_s: Any = (0.5, 6.0),
        slide_s: Any = (0.3, 1.2),
        slide_speed: Any = (0.3, 1.5),
        slide_direction_deg: Any = (60.0, 120.0),
        release_s: Any = (0.1, 0.4),
        set_down_fraction: float = 0.0,
        set_down_s: Any = (4.0, 7.0),
        objects: int = 12,
        object_seed: int = 0,
        contact_radius: Any = (2.0, 4.0),
        drag: Any = (0.03, 0.15),
        kinetic_ratio: Any = (0.5, 0.9),
        spread: Any = (0.01, 0.05),
        width_px: int = 200,
        height_px: int = 150,
        pitch_px: Any = (17.0, 24.0),
        grid_angle_deg: Any = (-3.0, 3.0),
        layout_jitter: float = 0.03,
        contact_offset: float = 1.0,
        n_pins: int = 30,
        snap: float = 0.35,
    ) -> None:
        m = "model."
        self.rate_hz = _scalar(rate_hz, m + "rate_hz")
        self.duration_s = _scalar(duration_s, m + "duration_s")
        self.n_frames = round(self.duration_s * self.rate_hz)
        if self.n_frames < 20:
            raise SimulationError(
                "model.duration_s * model.rate_hz must give >= 20 frames; "
                f"got {self.n_frames}"
            )
        self.slip_fraction = params.number(
            m + "slip_fraction", slip_fraction, lo=0.0, hi=1.0
        )
        self.onset_s = _range(onset_s, m + "onset_s", strict=False)
        self.slide_s = _range(slide_s, m + "slide_s")
        self.slide_speed = _range(slide_speed, m + "slide_speed", strict=False)
        self.slide_direction_deg = _range(
            slide_direction_deg, m + "slide_direction_deg", lo=-360.0, strict=False
        )
        self.release_s = _range(release_s, m + "release_s")
        self.set_down_fraction = params.number(
            m + "set_down_fraction", set_down_fraction, lo=0.0, hi=1.0
        )
        self.set_down_s = _range(set_down_s, m + "set_down_s", strict=False)
        for key, r in (("onset_s", self.onset_s), ("set_down_s", self.set_down_s)):
            if r[1] >= self.duration_s:
                raise SimulationError(
                    f"model.{key} ({r[1]:g} s) must end before model.duration_s "
                    f"({self.duration_s:g} s)"
                )
        self.objects = int(_scalar(objects, m + "objects", lo=1.0, strict=False))
        self.object_seed = int(
            _scalar(object_seed, m + "object_seed", lo=0.0, strict=False)
        )
        ranges = {
            "contact_radius": _range(contact_radius, m + "contact_radius"),
            "drag": _range(drag, m + "drag", strict=False),
            "kinetic_ratio": params.value_range(
                m + "kinetic_ratio", kinetic_ratio, lo=0.0, hi=1.0
            ),
            "spread": _range(spread, m + "spread", strict=False),
        }
        self.object_table = self._objects(ranges)
        self.width_px = int(_scalar(width_px, m + "width_px", lo=32.0, strict=False))
        self.height_px = int(_scalar(height_px, m + "height_px", lo=32.0, strict=False))
        self.pitch_px = _range(pitch_px, m + "pitch_px", lo=4.0, strict=False)
        if self.pitch_px[1] * 3 > min(self.width_px, self.height_px):
            raise SimulationError(
                f"model.pitch_px ({self.pitch_px[1]:g} px) must fit 3 pitches into the "
                f"frame ({self.width_px} x {self.height_px} px)"
            )
        self.grid_angle_deg = _range(
            grid_angle_deg, m + "grid_angle_deg", lo=-45.0, strict=False
        )
        self.layout_jitter = _scalar(
            layout_jitter, m + "layout_jitter", lo=0.0, strict=False
        )
        self.contact_offset = _scalar(
            contact_offset, m + "contact_offset", lo=0.0, strict=False
        )
        self.n_pins = int(_scalar(n_pins, m + "n_pins", lo=4.0, strict=False))
        self.snap = _scalar(snap, m + "snap")

    def _objects(self, ranges: Mapping[str, Range]) -> list[dict[str, float]]:
        """The objects' properties, drawn from ``object_seed`` alone (not the run's seed)."""
        out = []
        for k in range(self.objects):
            rng = np.random.default_rng([self.object_seed, k])
            out.append({key: _draw(rng, ranges[key]) for key in OBJECT_KEYS})
        return out

    def object_name(self, k: int) -> str:
        return f"object_{k:02d}"

    def streams(self) -> dict[str, StreamSpec]:
        """``camera_0``, ``camera_2`` and ``fingertips``: pin positions (px), as the
        importer writes."""
        channels = pin_channels(self.n_pins)
        return {
            **{
                cam: StreamSpec(
                    cam,
                    channels,
                    dict.fromkeys(channels, "px"),
                    rate_hz=self.rate_hz,
                    description=f"simulated GelSight fingertip {cam}: tracked pin positions, px",
                )
                for cam in CAMERAS
            },
            FINGERTIPS: fingertips_spec(
                CAMERAS, self.n_pins, self.rate_hz, "simulated "
            ),
        }

    def labels(self) -> dict[str, LabelSpec]:
        return {
            "slipped": LabelSpec(
                "slipped", description="1: the object slipped out, 0: wiggled only"
            ),
            "slip_onset_s": LabelSpec(
                "slip_onset_s",
                unit="s",
                description="when the object starts to slide (NaN: no slip)",
            ),
        }

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """Object, label and the timing of the slip or set-down of one trial."""
        k = int(rng.integers(self.objects))
        slipped = bool(rng.uniform() < self.slip_fraction)
        out: dict[str, Any] = {"object_index": k, "slipped": slipped}
        if slipped:
            out.update(
                onset_s=_draw(rng, self.onset_s),
                slide_s=_draw(rng, self.slide_s),
                slide_speed=_draw(rng, self.slide_speed),
                direction_rad=np.deg2rad(_draw(rng, self.slide_direction_deg)),
                release_s=_draw(rng, self.release_s),
            )
        elif self.set_down_fraction > 0 and rng.uniform() < self.set_down_fraction:
            out.update(
                set_down_s=_draw(rng, self.set_down_s),
                release_s=_draw(rng, self.release_s),
            )
        return out

    def _kinematics(
        self, p: Mapping[str, Any], t: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Load share (n,), slide (n, 2; pitches) and static-drag scale (n,) over time."""
        load = np.ones_like(t)
        slide = np.zeros((len(t), 2))
        drag_scale = np.ones_like(t)
        obj = self.object_table[int(p["object_index"])]
        leave = None
        if p["slipped"]:
            t0, dur = float(p["onset_s"]), float(p["slide_s"])
            s = np.clip(t - t0, 0.0, dur) * float(p["slide_speed"])
            u = np.array([np.cos(p["direction_rad"]), np.sin(p["direction_rad"])])
            slide = s[:, None] * u[None, :]
            drag_scale = np.where(t >= t0, obj["kinetic_ratio"], 1.0)
            leave = t0 + dur
        elif "set_down_s" in p:
            leave = float(p["set_down_s"])
        if leave is not None:
            load = np.clip(1.0 - (t - leave) / float(p["release_s"]), 0.0, 1.0)
        return load, slide, drag_scale

    def base(self, p: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        """Kinematics and each fingertip's marker grid at rest (markers do not move yet)."""
        t = sample_times(self.duration_s, self.rate_hz)
        load, slide, drag_scale = self._kinematics(p, t)
        obj = self.object_table[int(p["object_index"])]
        cams: dict[str, dict[str, Any]] = {}
        signals: dict[str, np.ndarray] = {}
        for cam in CAMERAS:
            pitch = _draw(rng, self.pitch_px)
            angle = np.deg2rad(_draw(rng, self.grid_angle_deg))
            offset = rng.uniform(-0.5, 0.5, size=2) * pitch
            rest = rest_grid(self.width_px, self.height_px, pitch, angle, offset)
            rest = rest + rng.normal(0.0, self.layout_jitter * pitch, size=rest.shape)
            r = self.contact_offset * np.sqrt(rng.uniform())
            phi = rng.uniform(0.0, 2 * np.pi)
            centre = np.array([self.width_px / 2.0, self.height_px / 2.0]) + (
                r * pitch * np.array([np.cos(phi), np.sin(phi)])
            )
            cams[cam] = {
                "pitch_px": pitch,
                "contact_px": centre,
                "mirror": cam != CAMERAS[0],
            }
            signals[f"markers_{cam}"] = np.repeat(rest[None], len(t), axis=0)
        drag_dir = np.array([0.0, 1.0])  # the object's weight pulls it down
        return SceneState(
            time={cam: t for cam in CAMERAS},
            signals={
                **signals,
                "load": load,
                "slide": slide,
                "drag": obj["drag"] * drag_scale[:, None] * drag_dir[None, :],
                "twist": np.zeros_like(t),
            },
            truth={
                **p,
                **obj,
                "object": self.object_name(int(p["object_index"])),
                "cameras": cams,
                "frame_size": (self.height_px, self.width_px),
            },
        )

    def _pins(self, cam: str, state: SceneState) -> tuple[np.ndarray, dict[str, float]]:
        """(n, 2K) pin rows of one fingertip: tracked in the frames when ``marker_grid``
        drew them, else the true positions of the pins the tracker would pick."""
        frames = state.signals.get(f"frames_{cam}")
        k = self.n_pins
        if frames is not None:
            grey = [
                np.clip(np.rint(f), 0, 255).astype(np.uint8) for f in np.asarray(frames)
            ]
            tr = track_frames(grey, n_pins=k, snap=self.snap, where=f"trial {cam}")
            pos = tr.positions
            info = {
                "markers_first_frame": float(tr.found[0]),
                "markers_found_mean": float(np.mean(tr.found)),
                "matched_mean": float(np.mean(tr.matched)),
            }
        else:
            marks = np.asarray(state.signals[f"markers_{cam}"])
            h, w = state.truth["frame_size"]
            first = marks[0]
            inside = (
                (first[:, 0] >= 0)
                & (first[:, 0] < w)
                & (first[:, 1] >= 0)
                & (first[:, 1] < h)
            )
            idx = np.flatnonzero(inside)
            d = np.hypot(first[idx, 0] - w / 2, first[idx, 1] - h / 2)
            pick = idx[np.argsort(d)[:k]]
            pitch = float(state.truth["cameras"][cam]["pitch_px"])
            rows = np.round(first[pick, 1] / pitch)
            pick = pick[np.lexsort((first[pick, 0], rows))]
            pos = np.full((len(marks), k, 2), np.nan)
            pos[:, : len(pick)] = marks[:, pick]
            info = {}
        return np.concatenate([pos[:, :, 0], pos[:, :, 1]], axis=1), info

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        """Pin streams per fingertip, the labels and the object (the group)."""
        channels = list(pin_channels(self.n_pins))
        streams: dict[str, pd.DataFrame] = {}
        meta: dict[str, Any] = {"object": str(state.truth["object"])}
        for cam in CAMERAS:
            block, info = self._pins(cam, state)
            df = pd.DataFrame(block, columns=channels)
            df.insert(0, "t", state.time[cam])
            streams[cam] = df
            meta.update({f"{cam}.{k}": v for k, v in info.items()})
        streams[FINGERTIPS] = fingertips_frame(
            {cam: streams[cam] for cam in CAMERAS}, self.n_pins
        )
        slipped = bool(state.truth["slipped"])
        labels = {
            "slipped": float(slipped),
            "slip_onset_s": float(state.truth["onset_s"]) if slipped else float("nan"),
        }
        return streams, labels, meta


__all__ = ["GelSightGrasp", "rest_grid"]
