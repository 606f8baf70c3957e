"""docs/templates/stream_detector.py, the family template docs/extending.md points to,
works as it stands: fit, batch = streaming, graph = detector in onnxruntime."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

TEMPLATE = (
    Path(__file__).resolve().parents[1] / "docs" / "templates" / "stream_detector.py"
)


def _template():
    spec = importlib.util.spec_from_file_location("stream_detector_template", TEMPLATE)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _recordings(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Four recordings of a held force that drops at a known sample in two of them."""
    rng = np.random.default_rng(seed)
    X, y, seg = [], [], []
    for k in range(4):
        f = 5.0 + 0.02 * rng.standard_normal(200)
        label = np.zeros(200, dtype=int)
        if k % 2:
            f[120:] -= np.linspace(0.0, 3.0, 80)
            label[120:] = 1
        X.append(f[:, None])
        y.append(label)
        seg.append(np.full(200, k))
    return np.concatenate(X), np.concatenate(y), np.concatenate(seg)


def test_template_detector_fits_and_streams_as_it_batches():
    """The ROC threshold separates the drops; the streaming form decides as the batch."""
    mod = _template()
    X, y, seg = _recordings()
    det = mod.ForceDrop(window=8).fit(X, y, segments=seg)
    pred = det.predict(X, segments=seg)
    settled = (y == 1) & (np.arange(len(y)) % 200 >= 140)  # 20 samples into each drop
    assert pred[settled].all()
    assert not pred[(y == 0)].any()
    one = X[seg == 1]
    _, streamed = det.replay(one)
    assert (det.predict(one) == 1).tolist() == streamed.tolist()


def test_template_graph_decides_as_the_detector():
    """The exported graph passes slipkit's detector parity check."""
    from slipkit.export.detector_parity import check_detector_parity

    mod = _template()
    X, y, seg = _recordings()
    det = mod.ForceDrop(window=8).fit(X, y, segments=seg)
    graph = mod.export_force_drop(det)
    Xt, _, segt = _recordings(seed=1)
    report = check_detector_parity(det, graph, Xt, segments=segt)
    assert report["passed"], report
