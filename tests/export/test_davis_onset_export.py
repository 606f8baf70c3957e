"""The DAVIS onset rule's graph computes the detector's score on event frames."""

from __future__ import annotations

import numpy as np

from slipkit.baselines.davis_onset import DavisOnset
from slipkit.export import export
from slipkit.export.davis_onset import DavisOnsetScores
from slipkit.export.parity import run_graph


def test_graph_score_equals_detector_score() -> None:
    """Random sparse frames and a strip: the ONNX score equals DavisOnset's, signs included."""
    h, w = 30, 40
    rng = np.random.default_rng(0)
    frames = (rng.random((6, 2, h, w)) < 0.15) * rng.integers(1, 3, (6, 2, h, w))
    frames[0] = 0
    frames[0, 0, 5:25, 10:12] = 1  # a straight strip lost: slip
    frames[1, 0] = 0  # nothing lost
    det = DavisOnset(width_px=w, height_px=h, min_pos_px=6).fit(np.empty((0, 4)))
    scores = DavisOnsetScores(detector=det).fit()
    got = run_graph(export(scores), frames.astype(np.float32)).ravel()
    want = scores.decision_function(frames)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert want[0] > 0
    assert (want[1:] <= 0).all()
