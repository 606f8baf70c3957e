"""SlipTack onset detectors export as one linear filter of the raw float32 window (hop 1)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.families.sliptack.test_onset import pull, stack, training

from slipkit.export import export
from slipkit.export.detectors import (
    NO_SCORE,
    DetectorGraph,
    check_detector_parity,
    graph_scores,
)
from slipkit.export.parity import onnx_session
from slipkit.families.sliptack.onset import SlipTackOnset, SlipTackOnsetLogistic


def _fitted(cls: type[SlipTackOnset]) -> SlipTackOnset:
    X, y, seg = training()
    return cls(window=20).fit(X, y, segments=seg)


def _held_out() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(21)
    X, _, seg = stack([pull(rng, speed=v) for v in (10.0, 31.6, 100.0)])
    return X, seg


@pytest.mark.parametrize("cls", [SlipTackOnset, SlipTackOnsetLogistic])
def test_graph_decides_as_the_detector(cls: type[SlipTackOnset]) -> None:
    """On held-out pulls every decision of the graph agrees with the batch detector."""
    det = _fitted(cls)
    X, seg = _held_out()
    report = check_detector_parity(det, export(det), X, segments=seg)
    assert (True, 1.0) == (report["passed"], report["agreement"])


@pytest.mark.parametrize("cls", [SlipTackOnset, SlipTackOnsetLogistic])
def test_graph_frame_and_size(cls: type[SlipTackOnset]) -> None:
    """Window 20 frames of one channel, hop 1, first decision at frame 19, at most 9 nodes."""
    graph = export(_fitted(cls))
    assert isinstance(graph, DetectorGraph)
    assert (("batch", 20, 1), 1, 19, True) == (
        graph.input_shape,
        graph.hop,
        graph.first_decision,
        len(graph.model.graph.node) <= 9,
    )


def test_nan_window_scores_no_score() -> None:
    """A window holding a NaN frame scores NO_SCORE (the batch detector's -inf)."""
    det = _fitted(SlipTackOnset)
    graph = export(det)
    x, _ = pull(np.random.default_rng(5), speed=50.0, n=20)
    x[7] = np.nan
    session = onnx_session(graph)
    raw = graph.run_windows(session, x[None, :, None].astype(np.float32))
    assert (NO_SCORE, -np.inf) == (float(raw[0]), float(graph_scores(raw)[0]))
