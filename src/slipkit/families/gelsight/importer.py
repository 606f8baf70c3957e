"""GelSight slip-or-wiggle recordings into slipkit's dataset format.

Layout (the Incipient-Slip-Detection set, ``docs/families/gelsight.md``):
``<path>/<object>/<trial>/camera_0.avi`` and ``camera_2.avi`` (the two fingertips, 25
fps) and an empty ``slip.txt`` when the trial slipped. Each video is tracked
(:mod:`slipkit.families.gelsight.tracking`) and becomes one stream of pin positions.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from slipkit.data.dataset import Dataset, LabelSpec, StreamSpec
from slipkit.errors import SourceFormatError
from slipkit.families.gelsight.tracking import track_video

SOURCE = "https://github.com/amitparag/Incipient-Slip-Detection"
LICENSE = "BSD-2-Clause"
CAMERAS: tuple[str, ...] = ("camera_0", "camera_2")


def pin_channels(n_pins: int) -> tuple[str, ...]:
    """Channel names of a pin stream: ``x_0 .. x_{n-1}`` then ``y_0 .. y_{n-1}``."""
    return (*(f"x_{i}" for i in range(n_pins)), *(f"y_{i}" for i in range(n_pins)))


#: the stream holding every fingertip's pins side by side (for a detector reading them all)
FINGERTIPS = "fingertips"


def fingertips_spec(
    cameras: Sequence[str], n_pins: int, rate_hz: float, what: str = ""
) -> StreamSpec:
    """The :data:`FINGERTIPS` stream: ``<camera>_x_i``, ``<camera>_y_i`` of each camera
    in turn (each fingertip's block as its own stream orders it)."""
    channels = tuple(f"{cam}_{c}" for cam in cameras for c in pin_channels(n_pins))
    return StreamSpec(
        FINGERTIPS,
        channels,
        dict.fromkeys(channels, "px"),
        rate_hz=float(rate_hz),
        description=(
            f"{what}GelSight fingertips {', '.join(cameras)} side by side: tracked "
            "pin positions, image px, over the frames every fingertip holds"
        ),
    )


def fingertips_frame(frames: dict[str, pd.DataFrame], n_pins: int) -> pd.DataFrame:
    """One trial's :data:`FINGERTIPS` rows from its per-camera frames (``t`` and the pin
    channels; extra columns such as ``trial_id`` are kept from the first camera)."""
    n = min(len(df) for df in frames.values())
    channels = list(pin_channels(n_pins))
    first = next(iter(frames.values())).iloc[:n]
    head = first.drop(columns=channels).reset_index(drop=True)
    blocks = [
        df[channels].iloc[:n].add_prefix(f"{cam}_").reset_index(drop=True)
        for cam, df in frames.items()
    ]
    return pd.concat([head, *blocks], axis=1)


def _trial_dirs(root: Path, cameras: Sequence[str]) -> list[Path]:
    if not root.is_dir():
        raise SourceFormatError(f"{root}: not a folder of <object>/<trial>/ folders")
    dirs = sorted(
        d for obj in root.iterdir() if obj.is_dir() for d in obj.iterdir() if d.is_dir()
    )
    if not dirs:
        raise SourceFormatError(
            f"{root}: holds no <object>/<trial>/ folders with {', '.join(cameras)}.avi"
        )
    return dirs


def tracking_summary(
    per_video: dict[str, dict[str, dict[str, float]]],
) -> dict[str, dict[str, float]]:
    """Tracking accuracy over the videos of each fingertip (from :meth:`Tracking.summary`)."""
    out: dict[str, dict[str, float]] = {}
    cams = sorted({cam for trial in per_video.values() for cam in trial})
    for cam in cams:
        v = [trial[cam] for trial in per_video.values() if cam in trial]

        def col(key: str) -> np.ndarray:
            return np.array([x[key] for x in v], dtype=np.float64)  # noqa: B023

        out[cam] = {
            "videos": len(v),
            "markers_first_frame_min": float(col("markers_first_frame").min()),
            "markers_first_frame_median": float(np.median(col("markers_first_frame"))),
            "matched_mean": round(float(col("matched_mean").mean()), 4),
            "matched_min": round(float(col("matched_mean").min()), 4),
            "matched_last_mean": round(float(col("matched_last").mean()), 4),
            "drift_px_median": round(float(np.median(col("drift_px_median"))), 3),
            "drift_px_max": round(float(col("drift_px_median").max()), 3),
        }
    return out


def read_gelsight(
    path: Path | str,
    *,
    n_pins: int = 30,
    rate_hz: float = 25.0,
    cameras: Sequence[str] = CAMERAS,
    snap: float = 0.35,
) -> Dataset:
    """Read a folder of GelSight trials: one trial per ``<object>/<trial>/`` folder.

    Parameters
    ----------
    path : path-like
        The folder of object folders (``gelsight-slip/train``).
    n_pins : int
        Pins tracked per fingertip: the markers of the first frame nearest the image
        centre (a fixed channel count across sensors that show 35 to 88 markers).
    rate_hz : float
        Frame rate of the videos, Hz.
    cameras : sequence of str
        Video stems of the fingertips; each becomes one stream.
    snap : float
        Largest distance, in marker pitches, from a flow estimate to the detected
        marker it snaps to.

    Returns
    -------
    Dataset
        Sensor ``gelsight``; trial ids ``<object>/<trial>``; streams ``camera_0``,
        ``camera_2`` (``x_i``, ``y_i`` in px) and, with two or more cameras,
        ``fingertips`` (both side by side, :func:`fingertips_frame`); group ``object``; labels ``slipped``
        (1: ``slip.txt`` present) and ``slip_onset_s`` (NaN: not recorded). The
        provenance holds the tracking accuracy per fingertip
        (:func:`tracking_summary`).
    """
    root = Path(path)
    cameras = tuple(cameras)
    channels = pin_channels(int(n_pins))
    specs = {
        cam: StreamSpec(
            cam,
            channels,
            dict.fromkeys(channels, "px"),
            rate_hz=float(rate_hz),
            description=f"GelSight fingertip {cam}: tracked marker (pin) positions, image px",
        )
        for cam in cameras
    }
    if len(cameras) > 1:
        specs[FINGERTIPS] = fingertips_spec(cameras, int(n_pins), rate_hz)
    rows: list[dict[str, object]] = []
    parts: dict[str, list[pd.DataFrame]] = {name: [] for name in specs}
    tracking: dict[str, dict[str, dict[str, float]]] = {}
    for d in _trial_dirs(root, cameras):
        trial_id = f"{d.parent.name}/{d.name}"
        tracking[trial_id] = {}
        for cam in cameras:
            tr = track_video(d / f"{cam}.avi", n_pins=int(n_pins), snap=snap)
            n = len(tr.positions)
            block = np.concatenate(
                [tr.positions[:, :, 0], tr.positions[:, :, 1]], axis=1
            )
            df = pd.DataFrame(block, columns=list(channels))
            df.insert(0, "t", np.arange(n) / float(rate_hz))
            df.insert(0, "trial_id", trial_id)
            parts[cam].append(df)
            tracking[trial_id][cam] = tr.summary()
        if FINGERTIPS in parts:
            parts[FINGERTIPS].append(
                fingertips_frame({c: parts[c][-1] for c in cameras}, int(n_pins))
            )
        rows.append(
            {
                "trial_id": trial_id,
                "object": d.parent.name,
                "slipped": float((d / "slip.txt").exists()),
                "slip_onset_s": np.nan,
            }
        )
    labels = {
        "slipped": LabelSpec(
            "slipped", description="1: the trial slipped (slip.txt), 0: wiggled only"
        ),
        "slip_onset_s": LabelSpec(
            "slip_onset_s", unit="s", description="not recorded by the source: NaN"
        ),
    }
    return Dataset(
        sensor="gelsight",
        streams=specs,
        trials=pd.DataFrame(rows),
        tables={
            name: pd.concat(part, ignore_index=True) for name, part in parts.items()
        },
        labels=labels,
        groups=("object",),
        provenance={
            "source": SOURCE,
            "license": LICENSE,
            "path": str(root),
            "assumptions": [
                f"frames at {float(rate_hz):g} Hz (t = frame / rate_hz)",
                f"{int(n_pins)} pins per fingertip, the first frame's markers nearest "
                "the image centre, tracked by optical flow snapped to detected markers",
            ],
            "tracking": tracking_summary(tracking),
        },
    )


__all__ = [
    "CAMERAS",
    "FINGERTIPS",
    "fingertips_frame",
    "fingertips_spec",
    "pin_channels",
    "read_gelsight",
    "tracking_summary",
]
