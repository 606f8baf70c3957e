"""The DAVIS onset rule's graph decides as the detector, on every small area pair."""

from __future__ import annotations

import numpy as np

from slipkit.baselines.davis_onset import DavisOnset
from slipkit.export import export
from slipkit.export.davis_onset import DavisOnsetAreaRule
from slipkit.export.parity import run_graph


def test_graph_score_equals_detector_score() -> None:
    """The ONNX score equals DavisOnset.score and has its sign on a 0..79 px grid."""
    det = DavisOnset(min_pos_px=6, neg_ratio=0.25)
    pos, neg = np.meshgrid(np.arange(80.0), np.arange(80.0))
    areas = np.column_stack([pos.ravel(), neg.ravel()])
    rule = DavisOnsetAreaRule(min_pos_px=6, neg_ratio=0.25).fit()
    score = run_graph(export(rule), areas).ravel()
    want = det.score(areas[:, 0], areas[:, 1])
    assert want.tolist() == score.astype(np.float64).tolist()
    assert (want > 0).any()
    assert (want <= 0).any()
