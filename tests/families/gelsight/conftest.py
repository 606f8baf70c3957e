"""Synthetic GelSight videos: a grid of dark markers drawn with OpenCV, moved by a known field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

PITCH = 30.0


def grid(nx: int = 9, ny: int = 7) -> np.ndarray:
    xs = 40.0 + PITCH * np.arange(nx)
    ys = 30.0 + PITCH * np.arange(ny)
    return np.array([(x, y) for y in ys for x in xs])


def draw(points: np.ndarray, shape: tuple[int, int] = (240, 320)) -> np.ndarray:
    """One BGR frame: bluish lit gel with dark markers (radius 6 px) at ``points``."""
    img = np.full((*shape, 3), (150, 120, 60), np.uint8)
    for x, y in points:
        cv2.circle(
            img,
            (round(float(x) * 4), round(float(y) * 4)),
            24,
            (20, 20, 20),
            -1,
            cv2.LINE_AA,
            2,
        )
    return cv2.GaussianBlur(img, (3, 3), 0)


def write_video(path: Path, frames: list[np.ndarray], fps: float = 25.0) -> Path:
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    assert writer.isOpened()
    for f in frames:
        writer.write(f)
    writer.release()
    return path


def sliding(n: int = 20, speed: float = 0.8) -> list[np.ndarray]:
    """Frames of the grid sliding right by ``speed`` px per frame."""
    g = grid()
    return [draw(g + np.array([speed * i, 0.0])) for i in range(n)]


def make_trials(root: Path, n: int = 12) -> Path:
    """<root>/obj_a/exp_num_1 (slip: the grid slides) and obj_b/exp_num_1 (still)."""
    still = [draw(grid())] * n
    for obj, frames, slip in (("obj_a", sliding(n), True), ("obj_b", still, False)):
        d = root / obj / "exp_num_1"
        d.mkdir(parents=True)
        write_video(d / "camera_0.avi", frames)
        write_video(d / "camera_2.avi", frames)
        if slip:
            (d / "slip.txt").write_text("")
    return root


@pytest.fixture
def trials_folder(tmp_path: Path) -> Path:
    return make_trials(tmp_path / "gelsight")
