"""The learned SlipTack speed regressor exports: spectral features and regressor in one graph."""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from numpy.typing import NDArray
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.export import export
from slipkit.export.detectors import check_detector_parity, detector_windows
from slipkit.export.parity import onnx_session
from slipkit.export.registry import ExportError
from slipkit.families.sliptack.export.spectral import (
    SpectralSlipDetector,
    _feature_graph,
    export_spectral_speed,
    graph_speeds,
)
from slipkit.families.sliptack.spectral import SpectralSpeedRegressor
from slipkit.families.sliptack.speed import FixedNormalForceWarning, StickSlipSpeed

RATE = 1000.0


def _compose(name: str, overrides: list[str]) -> DictConfig:
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    GlobalHydra.instance().clear()
    return cfg


def _pull(f_hz: float, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """A stick-slip-like nib signal (mm): a sawtooth-ish tone with a harmonic, drift, noise."""
    t = np.arange(n) / RATE
    phase = 2 * np.pi * f_hz * t
    return (
        0.05 * np.sin(phase)
        + 0.02 * np.sin(2 * phase + 0.3)
        + 0.01 * t
        + rng.normal(0, 0.002, n)
    )


class Data(NamedTuple):
    """Training recordings (stacked, with segments and speeds) and held-out ones."""

    X: NDArray[np.float64]
    y: NDArray[np.float64]
    seg: NDArray[np.int_]
    held_out: list[NDArray[np.float64]]


@pytest.fixture(scope="module")
def data() -> Data:
    """Eight 1.5 s pulls at 18-60 Hz (speed = f / 2 mm/s) to fit, three held out (seed 0)."""
    rng = np.random.default_rng(0)
    n = 1500
    xs, ys, segs = [], [], []
    for i, f in enumerate(np.linspace(18.0, 60.0, 8)):
        xs.append(_pull(f, n, rng))
        ys.append(np.full(n, f / 2))
        segs.append(np.full(n, i))
    held = [_pull(f, n, rng)[:, None] for f in (25.0, 37.0, 52.0)]
    return Data(
        np.concatenate(xs)[:, None], np.concatenate(ys), np.concatenate(segs), held
    )


_FITTED: dict[str, SpectralSpeedRegressor] = {}


def _fit(data: Data, model: str) -> SpectralSpeedRegressor:
    """The regressor (``model``) fitted on ``data``: once per module, read-only after."""
    if model not in _FITTED:
        _FITTED[model] = SpectralSpeedRegressor(
            window=400, hop=50, model=model, max_iter=30, alpha=1e-3
        ).fit(data.X, data.y, segments=data.seg)
    return _FITTED[model]


@pytest.mark.parametrize("model", ["gbr", "ridge"])
@pytest.mark.parametrize("dft_dtype", ["float32", "float64"])
def test_graph_speed_equals_regressor_on_held_out_windows(
    data: Data, model: str, dft_dtype: str
) -> None:
    """At every runtime call on held-out pulls the graph's speed is the regressor's (mm/s)."""
    est = _fit(data, model)
    graph = export_spectral_speed(est, dft_dtype=dft_dtype)
    sess = onnx_session(graph)
    diffs = []
    for x in data.held_out:
        windows, inst = detector_windows(graph, x)
        out = sess.run([graph.score_output], {graph.input_name: windows})[0]
        diffs.append(np.abs(graph_speeds(out) - est.predict(x)[inst]))
    d = np.concatenate(diffs)
    assert [69, 0] == [len(d), int(np.sum(d > 1e-3))]


def test_graph_features_equal_the_regressors(data: Data) -> None:
    """Band powers, peak frequencies and f_d of the graph match SpectralSpeedRegressor.features."""
    est = _fit(data, "gbr")
    model = _feature_graph(est, 17, "float64")
    import onnxruntime as ort

    sess = ort.InferenceSession(
        model.SerializeToString(), providers=["CPUExecutionProvider"]
    )
    x = data.held_out[1]
    expected, ends = est.features(x)
    windows = np.stack([x[e - 399 : e + 1] for e in ends]).astype(np.float32)
    actual = sess.run(None, {"window": windows})[0].astype(np.float64)
    bands, peaks, fd = slice(0, 16), slice(16, 19), slice(19, 20)
    assert np.abs(actual[:, bands] - expected[:, bands]).max() < 1e-4
    assert expected[:, peaks].tolist() == actual[:, peaks].tolist()
    assert np.abs(actual[:, fd] - expected[:, fd]).max() < 1e-3


def test_slip_detector_decides_as_the_batch_rule(data: Data) -> None:
    """SpectralSlipDetector's graph: speed >= threshold on every call, as the batch detector."""
    est = _fit(data, "gbr")
    det = SpectralSlipDetector(speed=est, threshold=20.0).fit()
    graph = export(det)
    X = np.concatenate(data.held_out)
    seg = np.repeat(np.arange(3), 1500)
    report = check_detector_parity(det, graph, X, segments=seg)
    assert [("0", "1"), 20.0, 400, 50, 399, 1.0, 0] == [
        graph.classes,
        graph.threshold,
        graph.window,
        graph.hop,
        graph.first_decision,
        report["agreement"],
        report["n_finite_mismatch"],
    ]


def test_twiddle_dft_is_numpys_rfft() -> None:
    """The two-GEMM twiddle DFT's power equals |numpy.fft.rfft|^2 at every bin (float64)."""
    from slipkit.families.sliptack.export.spectral import twiddle_dft_matrices

    w = 1000
    x = np.random.default_rng(3).normal(0.0, 1.0, (2, w))
    f1, t, w2, n1, k2 = twiddle_dft_matrices(w)
    a = (f1 @ x.reshape(2, n1, w // n1)).reshape(2, n1, 2, 1, w // n1) * t
    y = (a.reshape(-1, 4 * (w // n1)) @ w2).reshape(2, n1, 2, k2)
    power = (y**2).sum(axis=2).reshape(2, -1)
    ks = (np.arange(n1)[:, None] + n1 * np.arange(k2)[None, :]).reshape(-1)
    pos = np.argsort(ks)[: w // 2 + 1]
    expected = np.abs(np.fft.rfft(x, axis=1)) ** 2
    np.testing.assert_allclose(power[:, pos], expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("dft_dtype", ["float32", "float64"])
def test_shared_dft_graph_speeds_equal_the_separate_dfts(
    data: Data, dft_dtype: str
) -> None:
    """One DFT for f_d and the features: the same speeds as two DFTs, NaN windows included."""
    est = _fit(data, "gbr")
    x = np.concatenate(data.held_out)
    x[700] = np.nan  # windows holding a NaN: f_d NaN -> 0, the sample -> 0
    speeds, flags = [], []
    for shared in (False, True):
        graph = export_spectral_speed(est, dft_dtype=dft_dtype, shared_dft=shared)
        windows, inst = detector_windows(graph, x)
        out = onnx_session(graph).run([graph.score_output], {"window": windows})[0]
        speeds.append(graph_speeds(out))
        flags.append(graph.features["shared_dft"])  # type: ignore[index]
    expected = est.predict(x)[inst]
    assert [False, True] == flags
    assert np.abs(speeds[1] - speeds[0]).max() <= 1e-4
    assert np.abs(speeds[1] - expected).max() <= 1e-3


def test_graph_without_the_f_d_feature_scores_as_the_regressor(data: Data) -> None:
    """f_d_feature=False: 19 features, no f_d nodes, the graph's speed is predict's."""
    est = SpectralSpeedRegressor(
        window=400, hop=50, max_iter=30, f_d_feature=False
    ).fit(data.X, data.y, segments=data.seg)
    graph = export_spectral_speed(est)
    x = data.held_out[0]
    windows, inst = detector_windows(graph, x)
    out = onnx_session(graph).run([graph.score_output], {"window": windows})[0]
    ops = {n.op_type for n in graph.model.graph.node}
    assert [19, False, False] == [
        est.features(x)[0].shape[1],
        graph.features["f_d_feature"],  # type: ignore[index]
        "CumSum" in ops,  # the f_d detrend and peak rule are CumSums
    ]
    assert np.abs(graph_speeds(out) - est.predict(x)[inst]).max() <= 1e-3


def test_analytic_estimator_is_refused() -> None:
    """export_spectral_speed names the class it needs when given the analytic estimator."""
    with pytest.warns(FixedNormalForceWarning):
        est = StickSlipSpeed().fit(np.zeros((1, 1)), np.full(1, np.nan))
    with pytest.raises(ExportError, match="SpectralSpeedRegressor"):
        export_spectral_speed(est)  # type: ignore[arg-type]


def test_tree_converter_shim_is_restored(data: Data) -> None:
    """After an export, skl2onnx's tree-node helper is its own again."""
    from skl2onnx.common import tree_ensemble

    before = tree_ensemble.add_node
    export(_fit(data, "gbr"))
    assert before is tree_ensemble.add_node


@pytest.mark.slow  # ~15-60 s: six simulated pulls, spectral features of every window
def test_train_export_replay_scores_as_the_regressor(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """sliptack_speed run of spectral_gbr -> slipkit export -> slipkit-run: the batch speeds."""
    from slipkit.export.commands import export_main
    from slipkit.families.sliptack.task import DEFAULT
    from slipkit.runtime.cli import main
    from slipkit.train.commands import train_main
    from slipkit.train.runs import read_run

    run = tmp_path / "run"
    train_main(
        _compose(
            "train",
            [
                "experiment=sliptack_speed",
                "~detector",
                "model=sliptack_spectral_gbr",
                "model.max_iter=30",
                "dataset.n_trials=6",
                f"run_dir={run}",
            ],
        )
    )
    out = tmp_path / "bundle"
    export_main(
        _compose("export", [f"run={run}", f"out={out}", "choose_session=false"])
    )
    raw = json.loads((out / "manifest.json").read_text())
    capsys.readouterr()
    with pytest.raises(SystemExit) as done:
        main([str(out), "--replay", str(out / "replay.npz"), "--jsonl"])
    lines = [
        json.loads(line)
        for line in capsys.readouterr().out.splitlines()
        if line.startswith("{")
    ]
    # The replay is one stream (trials back to back), as the loop sees it.
    frames = np.load(out / "replay.npz")["frames"].reshape(-1, 1)
    est = read_run(run).model[DEFAULT]
    graph = export(SpectralSlipDetector(speed=est).fit())
    inst = graph.instants(len(frames))
    expected = est.predict(frames)[inst]
    scores = np.array([d["score"] for d in lines])
    assert [1.0, 0, inst.tolist()] == [
        raw["training"]["parity"]["agreement"],
        done.value.code,
        [d["frame"] for d in lines],
    ]
    assert np.abs(scores - expected).max() < 1e-3
