"""Marker detection and tracking in GelSight videos (OpenCV; capture side, not the bundle).

The gel carries a square grid of dark markers (pins). :func:`detect_markers` finds them
in one frame by adaptive thresholding and connected components; :func:`track_video`
fixes a set of ``n_pins`` pins in the first frame (those nearest the image centre, in
row-major order) and follows them frame by frame with pyramidal Lucas-Kanade optical
flow, snapping each flow estimate to the nearest detected marker when one lies within
``snap`` marker pitches (flow alone drifts; detection alone swaps neighbours under fast
shear). A pin with neither keeps its last position.

Tracking quality per video (:class:`Tracking`): markers detected per frame, the share of
pins matched to a detected marker, and the flow drift (distance, px, from the flow
estimate to the marker it snapped to).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slipkit.errors import SourceFormatError

FloatArray = NDArray[np.float64]


def _cv2() -> Any:
    try:
        import cv2
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise SourceFormatError(
            "reading GelSight videos needs OpenCV: pip install 'slipkit[video]'"
        ) from exc
    return cv2


def detect_markers(
    gray: NDArray[np.uint8],
    *,
    block: int = 31,
    offset: float = 12.0,
    min_area: int = 15,
    max_area: int = 1500,
) -> FloatArray:
    """Centroids (n, 2; x, y in px) of the dark markers in one grey frame.

    Adaptive mean threshold (markers darker than their ``block`` x ``block``
    neighbourhood by ``offset`` grey levels; the gel's lighting varies across the image),
    an opening against speckle, then connected components of ``min_area`` to
    ``max_area`` pixels.
    """
    cv2 = _cv2()
    blur = cv2.GaussianBlur(gray, (5, 5), 0)
    mask = cv2.adaptiveThreshold(
        blur,
        255,
        cv2.ADAPTIVE_THRESH_MEAN_C,
        cv2.THRESH_BINARY_INV,
        int(block),
        float(offset),
    )
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    _, _, stats, centroids = cv2.connectedComponentsWithStats(mask)
    area = stats[1:, cv2.CC_STAT_AREA]
    keep = (area >= min_area) & (area <= max_area)
    return np.asarray(centroids[1:][keep], dtype=np.float64)


def marker_pitch(points: FloatArray) -> float:
    """Median distance from each marker to its nearest neighbour (the grid pitch, px)."""
    if len(points) < 2:
        return float("nan")
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


def _nearest(points: FloatArray, found: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Nearest detected marker to each point and its distance (inf when none found)."""
    if len(found) == 0:
        return points.copy(), np.full(len(points), np.inf)
    d = np.linalg.norm(points[:, None, :] - found[None, :, :], axis=-1)
    k = d.argmin(axis=1)
    return found[k], d[np.arange(len(points)), k]


@dataclass(frozen=True)
class Tracking:
    """Pin tracks of one video.

    Attributes
    ----------
    positions : ndarray (n_frames, n_pins, 2)
        x, y of every pin in every frame, px (NaN: a pin the first frame did not have).
    found : ndarray (n_frames,)
        Markers detected in each frame.
    matched : ndarray (n_frames,)
        Share of pins matched to a detected marker in each frame.
    drift_px : ndarray (n_frames,)
        Median distance from the flow estimate to the matched marker, px (NaN at frame 0).
    pitch_px : float
        Marker pitch in the first frame, px.
    """

    positions: FloatArray
    found: NDArray[np.int_]
    matched: FloatArray
    drift_px: FloatArray
    pitch_px: float

    def summary(self) -> dict[str, float]:
        """Tracking accuracy of the video, JSON-able."""
        pins = int(np.isfinite(self.positions[0, :, 0]).sum())
        return {
            "frames": len(self.found),
            "markers_first_frame": int(self.found[0]),
            "pins": pins,
            "pitch_px": round(self.pitch_px, 2),
            "matched_mean": round(float(np.mean(self.matched)), 4),
            "matched_last": round(float(self.matched[-1]), 4),
            "drift_px_median": round(float(np.nanmedian(self.drift_px)), 3)
            if len(self.found) > 1
            else 0.0,
        }


def _read_gray(path: Path) -> list[NDArray[np.uint8]]:
    cv2 = _cv2()
    if not path.is_file():
        raise SourceFormatError(f"{path}: missing video")
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise SourceFormatError(f"{path}: cannot open the video (frame 0)")
        declared = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        frames: list[NDArray[np.uint8]] = []
        while True:
            ok, frame = cap.read()
            if not ok or frame is None:
                break
            if frame.ndim == 3:
                frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            frames.append(np.ascontiguousarray(frame, dtype=np.uint8))
    finally:
        cap.release()
    if not frames:
        raise SourceFormatError(f"{path}: frame 0 is unreadable")
    if declared > 0 and len(frames) < declared:
        raise SourceFormatError(
            f"{path}: frame {len(frames)} is unreadable (the video declares {declared})"
        )
    return frames


def track_frames(
    frames: list[NDArray[np.uint8]],
    *,
    n_pins: int = 30,
    snap: float = 0.35,
    where: str = "video",
) -> Tracking:
    """Track ``n_pins`` pins through grey ``frames`` (see the module doc)."""
    cv2 = _cv2()
    first = detect_markers(frames[0])
    if len(first) < 4:
        raise SourceFormatError(
            f"{where}: frame 0 shows {len(first)} markers; at least 4 are needed"
        )
    pitch = marker_pitch(first)
    h, w = frames[0].shape[:2]
    order = np.argsort(np.hypot(first[:, 0] - w / 2, first[:, 1] - h / 2))
    pins = first[order[:n_pins]]
    # row-major order: rows of about one pitch, then x
    pins = pins[np.lexsort((pins[:, 0], np.round(pins[:, 1] / pitch)))]
    k = len(pins)
    n = len(frames)
    pos = np.full((n, n_pins, 2), np.nan)
    pos[0, :k] = pins
    found = np.zeros(n, dtype=int)
    matched = np.ones(n)
    drift = np.full(n, np.nan)
    found[0] = len(first)
    cur = pins.astype(np.float32).reshape(-1, 1, 2)
    lk = {
        "winSize": (21, 21),
        "maxLevel": 3,
        "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01),
    }
    for i in range(1, n):
        nxt, status, _ = cv2.calcOpticalFlowPyrLK(
            frames[i - 1], frames[i], cur, None, **lk
        )
        prev = cur.reshape(-1, 2).astype(np.float64)
        flow = nxt.reshape(-1, 2).astype(np.float64)
        ok = status.reshape(-1).astype(bool) & np.isfinite(flow).all(axis=1)
        est = np.where(ok[:, None], flow, prev)
        blobs = detect_markers(frames[i])
        found[i] = len(blobs)
        near, dist = _nearest(est, blobs)
        hit = dist <= snap * pitch
        new = np.where(hit[:, None], near, est)
        matched[i] = float(hit.mean())
        drift[i] = float(np.median(dist[hit])) if hit.any() else np.nan
        pos[i, :k] = new
        cur = new.astype(np.float32).reshape(-1, 1, 2)
    return Tracking(pos, found, matched, drift, pitch)


def track_video(path: Path | str, *, n_pins: int = 30, snap: float = 0.35) -> Tracking:
    """Read a GelSight video and track its pins (errors name the file and frame)."""
    path = Path(path)
    return track_frames(_read_gray(path), n_pins=n_pins, snap=snap, where=str(path))


__all__ = ["Tracking", "detect_markers", "marker_pitch", "track_frames", "track_video"]
