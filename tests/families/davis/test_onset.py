"""The DAVIS onset rule: a one-sided loss of contact is slip, a vibration incident is not."""

from __future__ import annotations

import numpy as np
import pytest

from slipkit.families.davis.onset import DavisOnset, onset_features, onset_score
from slipkit.families.davis.polarity import DavisPolarity

W, H = 60, 50


def _disc(cx: float, cy: float, r: float) -> np.ndarray:
    yy, xx = np.mgrid[0:H, 0:W]
    return (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r


def _events(masks: list[np.ndarray], frame_s: float) -> np.ndarray:
    """Events between consecutive contact masks, one frame apart: lost -> +1, gained -> -1."""
    rows = []
    for k in range(1, len(masks)):
        t = (k - 0.5) * frame_s
        for sign, sel in (
            (1.0, masks[k - 1] & ~masks[k]),
            (-1.0, masks[k] & ~masks[k - 1]),
        ):
            y, x = np.nonzero(sel)
            rows += [[t, xi, yi, sign] for xi, yi in zip(x, y, strict=True)]
    ev = np.array(rows, dtype=float).reshape(-1, 4)
    return ev[np.argsort(ev[:, 0], kind="stable")]


def _shrink(frame_s: float) -> np.ndarray:
    """A disc that loses contact from its right side, three pixel columns per frame."""
    base = _disc(30, 25, 15)
    xx = np.mgrid[0:H, 0:W][1]
    return _events([base & (xx <= 42 - 3 * k) for k in range(6)], frame_s)


def _vibration(frame_s: float) -> np.ndarray:
    """The whole disc shifts 3 px right and back: each frame loses and gains contact."""
    return _events([_disc(30 + s, 25, 15) for s in (0, 3, 0, 3, 0)], frame_s)


def _contraction(frame_s: float) -> np.ndarray:
    """The disc shrinks all round (a dilation's return): contact lost on the whole rim."""
    return _events([_disc(30, 25, r) for r in (16, 15, 14, 13)], frame_s)


def _onset() -> DavisOnset:
    return DavisOnset(width_px=W, height_px=H).fit(np.empty((0, 4)))


def test_one_sided_shrink_is_slip_and_vibration_is_not() -> None:
    """The shrink's frames are slip; a shift's and a contraction's are not, though the
    polarity rule calls them slip."""
    det = _onset()
    paper = DavisPolarity(width_px=W, height_px=H, frame_s=det.frame_s).fit(
        np.empty((0, 4))
    )
    got, paper_got = [], []
    for make in (_shrink, _vibration, _contraction):
        ev = make(det.frame_s)
        got.append(int(det.frames(ev)["slip"].sum()))
        paper_got.append(int(paper.frames(ev)["slip"].sum()) > 0)
    assert [5, 0, 0] == got
    assert [True, True, True] == paper_got


def test_curl_of_a_strip_and_a_ring() -> None:
    """Curl ~1 for a straight filled strip, large for a rim."""
    frames = np.zeros((2, 2, H, W))
    frames[0, 0, 10:30, 20:23] = 1
    frames[1, 0] = _disc(30, 25, 15) & ~_disc(30, 25, 13)
    curl = onset_features(frames)[:, 2]
    assert 0.8 < curl[0] < 1.2
    assert curl[1] > 5


def test_press_gaining_contact_is_not_slip() -> None:
    """A growing disc (the press) gives negative events only: no slip frame."""
    det = _onset()
    ev = _events([_disc(30, 25, r) for r in (6, 8, 10, 12, 14)], det.frame_s)
    assert 0 == int(det.frames(ev)["slip"].sum())


def test_stream_equals_batch() -> None:
    """Events pushed in uneven chunks give the batch frames."""
    det = _onset()
    ev = np.concatenate(
        [_vibration(det.frame_s), _shrink(det.frame_s) + np.array([0.03, 0, 0, 0])]
    )
    batch = det.frames(ev)
    stream = det.stream().feed(np.array_split(ev, 7))
    got = [(r.frame, r.pos_area_px, r.neg_area_px, r.curl, r.slip) for r in stream]
    cols = ["frame", "pos_area_px", "neg_area_px", "curl", "slip"]
    want = list(batch[cols].itertuples(index=False, name=None))
    assert want == got


@pytest.mark.parametrize(
    ("pos", "neg", "slip"),
    [(8, 2, True), (7, 0, False), (8, 3, False), (40, 10, True), (40, 11, False)],
)
def test_score_threshold(pos: int, neg: int, slip: bool) -> None:
    """Slip exactly when pos >= min_pos_px and neg <= neg_ratio pos (a straight strip)."""
    score = onset_score([pos, neg, 1.0], min_pos_px=8, neg_ratio=0.25, max_curl=5.0)
    assert slip == bool(score[0] > 0)


def test_bad_parameter_is_refused() -> None:
    """A negative ratio is a parameter error naming it."""
    with pytest.raises(ValueError, match="neg_ratio"):
        DavisOnset(neg_ratio=-1.0).fit(np.empty((0, 4)))
