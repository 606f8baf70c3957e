"""FSR onset detectors export as small float64 window graphs after press_sign (one-sample blocks)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from tests.baselines.test_conventions import fsr_trials, stack

from slipkit.export import export
from slipkit.export.detectors import (
    DetectorGraph,
    check_detector_parity,
    detector_windows,
    graph_scores,
)
from slipkit.export.parity import onnx_session
from slipkit.families.fsr.onset import FSROnset, FSROnsetLogistic
from slipkit.families.fsr.touch_slip import PolarityWarning
from slipkit.runtime.preprocessing import Pipeline


def _fitted(
    cls: type[FSROnset], mixed: bool
) -> tuple[FSROnset, np.ndarray, np.ndarray]:
    """Fitted on generated slides and bumps (both wirings when ``mixed``); held-out ones."""
    train = fsr_trials(100, 4, polarity="falling", slide=True) + fsr_trials(
        102, 2, polarity="falling", slide=False
    )
    held = fsr_trials(400, 3, polarity="falling", slide=True) + fsr_trials(
        500, 2, polarity="falling", slide=False
    )
    if mixed:
        train += fsr_trials(101, 4, polarity="rising", slide=True)
        held += fsr_trials(401, 3, polarity="rising", slide=True)
    X, y, seg = stack(train)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PolarityWarning)
        det = cls().fit(X, y, segments=seg)
    Xh, _, segh = stack(held)
    return det, Xh, segh


@pytest.mark.parametrize("cls", [FSROnset, FSROnsetLogistic])
@pytest.mark.parametrize("mixed", [False, True])
def test_graph_decides_as_the_detector(cls: type[FSROnset], mixed: bool) -> None:
    """On held-out recordings, through the runtime's press_sign, every decision agrees."""
    det, Xh, segh = _fitted(cls, mixed)
    graph = export(det)
    report = check_detector_parity(det, graph, Xh, segments=segh)
    assert (True, 1.0, True) == (
        report["passed"],
        report["agreement"],
        report["max_abs_diff"] < 1e-12,
    )


@pytest.mark.parametrize("mixed", [False, True])
def test_graph_reads_press_sign_every_sample(mixed: bool) -> None:
    """One step, press_sign with one-sample blocks (sign 0 for mixed wirings), hop 1, float64."""
    det, _, _ = _fitted(FSROnset, mixed)
    graph = export(det)
    assert isinstance(graph, DetectorGraph)
    step = dict(graph.preprocessing[0])
    assert (
        "press_sign",
        1,
        1,
        None if mixed else 1,
        1,
        det.window_samples,
        "float64",
        max(det.window_samples - 1, 9),
    ) == (
        step["op"],
        step["block"],
        step["hop"],
        step.get("sign"),
        graph.hop,
        graph.window,
        graph.input_dtype,
        graph.first_decision,
    )


@pytest.mark.parametrize(("cls", "most"), [(FSROnset, 11), (FSROnsetLogistic, 16)])
def test_graph_is_small(cls: type[FSROnset], most: int) -> None:
    """Node dispatch is a 2 kHz call's cost: at most 11 (analytic) / 16 (learned) nodes."""
    det, _, _ = _fitted(cls, False)
    assert len(export(det).model.graph.node) <= most


def test_a_window_with_nan_never_scores() -> None:
    """A window holding a NaN scores NO_SCORE or NaN, never a finite score."""
    det, Xh, _ = _fitted(FSROnset, False)
    graph = export(det)
    assert isinstance(graph, DetectorGraph)
    x = Xh[:3000].copy()
    x[2000] = np.nan
    windows, inst = detector_windows(graph, x)
    pipe = Pipeline(list(graph.preprocessing), (graph.window, 1), "graph")
    fed = np.stack([pipe(w[:, None]).reshape(-1) for w in windows])
    out = graph_scores(graph.run_windows(onnx_session(graph), fed))
    hit = (inst >= 2000) & (inst < 2000 + graph.window)
    assert 0 == int(np.isfinite(out[hit]).sum())
