"""ONNX export of the pin-count-independent TacTip estimators (detector and pooled SVM)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from slipkit.errors import SlipkitError
from slipkit.export import ExportError, check_parity, export
from slipkit.export.detectors import DetectorGraph, check_detector_parity
from slipkit.export.parity import run_graph
from slipkit.families.tactip.detector import PinMotionDetector
from slipkit.families.tactip.export.svm import export_tactip_svm
from slipkit.families.tactip.features import DatasetFeatures
from slipkit.families.tactip.task import _check_pin_count
from slipkit.features.pins import pooled_features, velocity_features
from slipkit.models import TacTipSVM

sys.path.insert(0, str(Path(__file__).parents[1] / "baselines"))
from tests.families.tactip.test_detector import stretch_then_snap


def recordings(
    n_pins: int, n: int = 3, first_seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` stretch-and-snap recordings with a few NaN pins, stacked, with segments."""
    parts = [stretch_then_snap(n_pins, seed=first_seed + s) for s in range(n)]
    X = np.vstack([p[0] for p in parts])
    X[7, 1] = np.nan
    X[100, [0, n_pins]] = np.nan
    X[130, :] = np.nan
    y = np.concatenate([p[1] for p in parts])
    seg = np.repeat(np.arange(n), len(parts[0][0]))
    return X, y, seg


@pytest.mark.parametrize("score", ["reversal", "coherent"])
def test_pin_motion_graph_decides_as_the_batch_detector(score: str) -> None:
    """Through the registry, the window graph agrees with decision_function on every frame, NaN pins included."""
    X, y, seg = recordings(23)
    det = PinMotionDetector(score=score, lookback=6).fit(X, y, segments=seg)
    graph = export(det)
    X, _, seg = recordings(
        23, first_seed=10
    )  # held out: no score sits on the threshold
    assert isinstance(graph, DetectorGraph)
    assert ("batch", det.window, 46) == graph.input_shape
    report = check_detector_parity(det, graph, X, segments=seg)
    assert (True, 0, 0) == (
        report["passed"],
        report["n_disagree"],
        report["n_finite_mismatch"],
    )


def test_pin_motion_exports_for_another_pin_count() -> None:
    """Fitted on 19 pins, exported for 61: parity holds on 61-pin recordings."""
    X19, y19, seg19 = recordings(19)
    det = PinMotionDetector().fit(X19, y19, segments=seg19)
    graph = export(det, n_pins=61)
    X61, _, seg61 = recordings(61, first_seed=10)
    assert 61 == graph.features["n_pins"]
    report = check_detector_parity(det, graph, X61, segments=seg61)
    assert (True, 0) == (report["passed"], report["n_disagree"])


def _pairs(X: np.ndarray) -> np.ndarray:
    return np.stack([X[:-1], X[1:]], axis=1)


def _features(pairs: np.ndarray) -> np.ndarray:
    n = pairs.shape[-1] // 2
    p = pairs.reshape(len(pairs), 2, 2, n).transpose(0, 1, 3, 2)
    return velocity_features(p[:, 1] - p[:, 0])


def test_pooled_svm_trained_on_one_pin_count_exports_for_another() -> None:
    """A pooled SVM fitted on 19-pin features scores 61-pin raw frames in the graph as in numpy."""
    X19, y19, _ = recordings(19)
    F19 = _features(_pairs(X19))
    labels = np.where(y19[1:] > 0, "slip", "static")
    svm = TacTipSVM(features="pooled", standardize=True, gamma="scale", C=10.0).fit(
        F19, labels
    )
    X61, _, _ = recordings(61)
    pairs = _pairs(X61).astype(np.float32)
    graph = export_tactip_svm(svm, with_features=True, n_pins=61)
    assert ("batch", 2, 122) == graph.input_shape
    report = check_parity(svm, graph, pairs)
    assert (True, 0) == (report["passed"], report["n_disagree"])
    feats = export_tactip_svm(svm, n_pins=61)  # per-pin features in, pooled inside
    F61 = _features(pairs.astype(np.float64))
    np.testing.assert_allclose(
        run_graph(feats, F61.astype(np.float32)),
        svm.decision_function(F61),
        rtol=1e-4,
        atol=1e-4,
    )
    assert (len(F61), 6) == pooled_features(F61).shape


def test_pooled_svm_export_needs_the_pin_count() -> None:
    """Without n_pins a pooled SVM cannot be exported: the error names the option."""
    X19, y19, _ = recordings(19)
    labels = np.where(y19[1:] > 0, "slip", "static")
    svm = TacTipSVM(features="pooled", gamma="scale").fit(
        _features(_pairs(X19)), labels
    )
    with pytest.raises(ExportError, match="needs n_pins"):
        export_tactip_svm(svm)


def test_per_pin_svm_refuses_another_pin_count_naming_both() -> None:
    """A per-pin SVM exported or scored for another pin count raises an error naming both counts."""
    X19, y19, _ = recordings(19)
    F19 = _features(_pairs(X19))
    labels = np.where(y19[1:] > 0, "slip", "static")
    svm = TacTipSVM().fit(F19, labels)
    with pytest.raises(ExportError, match=r"\(19 pins\); the stream has 61 pins"):
        export_tactip_svm(svm, with_features=True, n_pins=61)
    F61 = _features(_pairs(recordings(61)[0]))
    feats = DatasetFeatures(F61, labels, np.zeros(len(F61)), np.zeros(len(F61), str))
    with pytest.raises(SlipkitError, match=r"trained on 19 pins .* has 61 pins"):
        _check_pin_count(svm, feats, "dr_dtheta")
    pooled = TacTipSVM(features="pooled", gamma="scale").fit(F19, labels)
    assert _check_pin_count(pooled, feats, "dr_dtheta") is None
