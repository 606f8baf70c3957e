"""The SlipTack speed graph (``slipkit.families.sliptack.export.speed``): parity with the batch estimator, edge cases, bundle."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray
from omegaconf import DictConfig

from slipkit import config_dir
from slipkit.export.detectors import NO_SCORE, DetectorGraph, detector_windows
from slipkit.export.parity import onnx_session
from slipkit.export.registry import exporter_for
from slipkit.families.sliptack.export.detector import (
    SpeedSlipDetector,
    export_speed_slip_detector,
)
from slipkit.families.sliptack.export.speed import (
    dft_matrices,
    export_stick_slip_speed,
    graph_speeds,
    peak_ranks,
)
from slipkit.families.sliptack.speed import StickSlipSpeed

RATE = 1000.0
W = 1000
#: The detector config's settings (configs/detector/sliptack_frequency.yaml) without
#: the harmonic check and interpolation (:data:`REFINED`, tested on their own).
PARAMS: dict[str, Any] = {
    "rate_hz": RATE,
    "window": W,
    "hop": 10,
    "f_max_range": (15.0, 100.0),
    "min_peak_ratio": 0.6,
}
#: Speeds agree within this relative difference (the speed table is built for 1e-7).
SPEED_RTOL = 1e-6
#: The issue-14 peak rules the shipped config adds (harmonic check, interpolation).
REFINED: dict[str, Any] = {"harmonics": "fundamental", "interpolate": True}


def _fitted(**params: Any) -> StickSlipSpeed:
    return StickSlipSpeed(**{**PARAMS, **params}).fit(
        np.zeros((1, 1)), np.full(1, np.nan)
    )


def _compose(name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    GlobalHydra.instance().clear()
    return cfg


def _run(
    graph: DetectorGraph, windows: NDArray[Any], session: Any = None
) -> NDArray[np.float64]:
    sess = session if session is not None else onnx_session(graph)
    out = sess.run(
        [graph.score_output], {graph.input_name: np.asarray(windows, np.float32)}
    )
    return graph_speeds(out[0])


def _sine(
    freq_hz: float, amp: float = 0.05, offset: float = 0.3
) -> NDArray[np.float64]:
    t = np.arange(W) / RATE
    return offset + amp * np.sin(2 * np.pi * freq_hz * t + 0.3)


@pytest.fixture(scope="module")
def estimator() -> StickSlipSpeed:
    """The detector config's estimator with the physics stick length."""
    return _fitted()


@pytest.fixture(scope="module")
def graphs(estimator: StickSlipSpeed) -> dict[str, tuple[DetectorGraph, Any]]:
    """Speed and frequency graphs with their sessions."""
    out = {}
    for q in ("speed", "frequency"):
        g = export_stick_slip_speed(estimator, quantity=q)
        out[q] = (g, onnx_session(g))
    return out


@pytest.fixture(scope="module")
def pulls() -> list[NDArray[np.float64]]:
    """Nib deflection (mm) of 3 simulated ``sliptack_pull`` trials (seed 2)."""
    from slipkit.sim.commands import build_scene

    cfg = _compose("simulate", ["scene=sliptack_pull"])
    ds = build_scene(cfg.scene).simulate(3, seed=2)
    return [tr.streams["nib"]["deflection"].to_numpy(dtype=np.float64) for tr in ds]


def test_dft_matrices_reproduce_numpy_rfft() -> None:
    """The two-stage factorised DFT equals numpy's rfft bin for bin."""
    x = np.random.default_rng(0).normal(size=W)
    f1, g, n1, k2 = dft_matrices(W)
    a = f1 @ x.reshape(n1, -1)
    n2 = W // n1
    ri = np.concatenate([a[:n1], a[n1:]], axis=1)[:, None, :]  # (N1, 1, 2 N2)
    y = (ri @ g)[:, 0, :]  # (N1, 2 K2)
    spec = (y[:, :k2] + 1j * y[:, k2:]).T.reshape(-1)[: W // 2 + 1]
    assert (25, 40) == (n1, n2)
    np.testing.assert_allclose(spec, np.fft.rfft(x), rtol=0, atol=1e-10)


@pytest.mark.parametrize("quantity", ["speed", "frequency"])
def test_graph_matches_batch_on_simulated_pulls(
    quantity: str,
    estimator: StickSlipSpeed,
    graphs: dict[str, tuple[DetectorGraph, Any]],
    pulls: list[NDArray[np.float64]],
) -> None:
    """At the runtime's call instants the graph's speed / f_d equals the batch estimator's."""
    graph, sess = graphs[quantity]
    for x in pulls:
        ref_all = (
            estimator.predict(x[:, None])
            if quantity == "speed"
            else estimator.frequency(x[:, None])
        )
        windows, inst = detector_windows(graph, x[:, None])
        ours, ref = _run(graph, windows, sess), ref_all[inst]
        assert np.array_equal(np.isfinite(ref), np.isfinite(ours))
        assert np.isfinite(ref).mean() > 0.9
        np.testing.assert_allclose(ours, ref, rtol=SPEED_RTOL, equal_nan=True)


@pytest.mark.parametrize("quantity", ["speed", "frequency"])
def test_refined_peaks_graph_matches_batch(
    quantity: str, pulls: list[NDArray[np.float64]]
) -> None:
    """With the harmonic check and interpolation the graph equals the batch estimator, also on a 0.63 harmonic."""
    est = _fitted(**REFINED)
    graph = export_stick_slip_speed(est, quantity=quantity)
    sess = onnx_session(graph)
    t = np.arange(3000) / RATE
    harmonic = (
        0.1 * np.sin(2 * np.pi * 31.3 * t)
        + 0.063 * np.sin(2 * np.pi * 62.6 * t + 1.0)
        + np.random.default_rng(0).normal(0, 0.01, len(t))
    )
    for x in [*pulls, harmonic]:
        ref_all = (
            est.predict(x[:, None])
            if quantity == "speed"
            else est.frequency(x[:, None])
        )
        windows, inst = detector_windows(graph, x[:, None])
        ours, ref = _run(graph, windows, sess), ref_all[inst]
        assert np.array_equal(np.isfinite(ref), np.isfinite(ours))
        np.testing.assert_allclose(ours, ref, rtol=SPEED_RTOL, equal_nan=True)
    f = est.frequency(harmonic[:, None])
    assert 31.3 == pytest.approx(float(np.nanmedian(f)), rel=0.01)


def test_force_input_does_not_export() -> None:
    """normal_force='input' has no graph: a clear ExportError."""
    from slipkit.export.registry import ExportError

    est = StickSlipSpeed(**PARAMS, normal_force="input").fit(
        np.zeros((1, 2)), np.full(1, np.nan)
    )
    with pytest.raises(ExportError, match="normal_force='input'"):
        export_stick_slip_speed(est)


def test_float64_dft_agrees_with_float32(
    estimator: StickSlipSpeed, pulls: list[NDArray[np.float64]]
) -> None:
    """The float64 DFT option gives the same speeds as the default float32 one."""
    g32 = export_stick_slip_speed(estimator)
    g64 = export_stick_slip_speed(estimator, dft_dtype="float64")
    windows, _ = detector_windows(g32, pulls[0][:, None])
    np.testing.assert_allclose(_run(g64, windows), _run(g32, windows), rtol=1e-12)


@settings(max_examples=15, deadline=None)
@given(
    freq=st.integers(min_value=16, max_value=99),
    amp=st.floats(min_value=1e-3, max_value=1.0),
    offset=st.floats(min_value=-5.0, max_value=5.0),
)
def test_pure_sinusoid_gives_its_frequency(
    freq: int,
    amp: float,
    offset: float,
    estimator: StickSlipSpeed,
    graphs: dict[str, tuple[DetectorGraph, Any]],
) -> None:
    """A sine on a DFT bin: f_d is that frequency and the speed eq. 3's, in graph and batch."""
    x = _sine(float(freq), amp, offset)
    graph, sess = graphs["frequency"]
    f_graph = float(_run(graph, x[None, :, None], sess)[0])
    assert float(freq) == pytest.approx(f_graph, abs=1e-9)
    assert estimator.segment_frequency(x) == pytest.approx(f_graph, abs=1e-9)
    graph, sess = graphs["speed"]
    v_graph = float(_run(graph, x[None, :, None], sess)[0])
    v_ref = float(estimator.speed_from_frequency(float(freq))[0])
    assert v_ref == pytest.approx(v_graph, rel=SPEED_RTOL)


def test_saturation_is_no_score() -> None:
    """A frequency above saturation (130.8 Hz) has no speed: NaN in batch, NO_SCORE in the graph."""
    est = _fitted(f_max_range=(15.0, 200.0))
    x = _sine(150.0)
    g = export_stick_slip_speed(est)
    out = onnx_session(g).run(
        [g.score_output], {g.input_name: x[None, :, None].astype(np.float32)}
    )[0]
    assert est.saturation_hz_ < 150.0
    assert np.isnan(est.predict(x[:, None])[-1])
    assert NO_SCORE == float(out[0])
    f_graph = _run(export_stick_slip_speed(est, quantity="frequency"), x[None, :, None])
    assert 150.0 == pytest.approx(float(f_graph[0]), abs=1e-9)


def test_paper_form_is_the_closed_form() -> None:
    """form='paper': the graph's speed equals the batch closed-form inversion."""
    est = _fitted(form="paper")
    x = _sine(40.0)
    v = _run(export_stick_slip_speed(est), x[None, :, None])
    assert float(est.speed_from_frequency(40.0)[0]) == pytest.approx(
        float(v[0]), rel=SPEED_RTOL
    )


@pytest.mark.parametrize("case", ["constant", "nan", "inf", "noise_free_zero"], ids=str)
def test_undefined_windows_score_no_score(
    case: str, estimator: StickSlipSpeed, graphs: dict[str, tuple[DetectorGraph, Any]]
) -> None:
    """Constant, NaN- or inf-holding windows: the batch gives NaN and the graph NO_SCORE."""
    x = {
        "constant": np.full(W, 0.42),
        "nan": np.where(np.arange(W) == 500, np.nan, _sine(30.0)),
        "inf": np.where(np.arange(W) == 7, np.inf, _sine(30.0)),
        "noise_free_zero": np.zeros(W),
    }[case]
    assert np.isnan(estimator.segment_frequency(x))
    for graph, sess in graphs.values():
        out = sess.run(
            [graph.score_output],
            {graph.input_name: x[None, :, None].astype(np.float32)},
        )
        assert NO_SCORE == float(out[0][0])


def test_registry_finds_the_exporters(estimator: StickSlipSpeed) -> None:
    """The registry maps StickSlipSpeed and SpeedSlipDetector to this module's exporters."""
    det = SpeedSlipDetector(speed=estimator, threshold=5.0).fit()
    assert export_stick_slip_speed is exporter_for(estimator)
    assert export_speed_slip_detector is exporter_for(det)
    graph = exporter_for(det)(det)
    assert isinstance(graph, DetectorGraph)
    assert [W, 10, W - 1] == [graph.window, graph.hop, graph.first_decision]
    assert {
        "rule": "threshold",
        "threshold": 5.0,
        "strict": False,
        "classes": ["0", "1"],
    }.items() <= (graph.decision() or {}).items()


def test_speed_slip_detector_decides_speed_at_threshold(
    estimator: StickSlipSpeed, pulls: list[NDArray[np.float64]]
) -> None:
    """The wrapper's score is the speed (-inf where undefined), slip where >= threshold."""
    x = pulls[0][:, None]
    det = SpeedSlipDetector(speed=estimator, threshold=30.0).fit()
    v = estimator.predict(x)
    score = det.decision_function(x)
    assert np.array_equal(np.where(np.isfinite(v), v, -np.inf), score)
    assert np.array_equal((score >= 30.0).astype(int), det.predict(x))


def test_export_bundle_loop_decides_as_the_batch_estimator(tmp_path: Path) -> None:
    """Tiny run -> export_main -> bundle; the runtime loop's decisions equal the reference."""
    from slipkit.export.commands import export_main
    from slipkit.runtime import StreamLoop, load_bundle
    from slipkit.train.commands import train_main
    from slipkit.train.runs import read_run

    run = tmp_path / "run"
    train_main(
        _compose(
            "train",
            ["experiment=sliptack_speed", "dataset.n_trials=6", f"run_dir={run}"],
        )
    )
    out = tmp_path / "bundle"
    export_main(
        _compose(
            "export",
            [
                f"run={run}",
                f"out={out}",
                "choose_session=false",
                "regression.threshold=50.0",
            ],
        )
    )
    bundle = load_bundle(out)
    raw = json.loads((out / "manifest.json").read_text())
    replay = np.load(out / "replay.npz")
    frames, times = replay["frames"], replay["timestamps"]
    loop = StreamLoop(bundle)
    for values, ts in zip(frames, times, strict=True):
        loop.step(values, float(ts))
    res = loop.result()
    est = read_run(run).model["*"]
    det = SpeedSlipDetector(speed=est, threshold=50.0).fit()
    ref = det.decision_function(frames)[res.frame]
    assert [W, 10, [1], "1", 50.0] == [
        raw["frame"]["window"],
        raw["frame"]["hop"],
        raw["frame"]["shape"],
        raw["decision"]["positive"],
        raw["threshold"],
    ]
    assert 1.0 == raw["training"]["parity"]["agreement"]
    assert len(res.frame) > 100
    assert np.array_equal(ref >= 50.0, res.slip)
    assert 0 < int(res.slip.sum()) < len(res.slip)  # both decisions occur
    finite = np.isfinite(ref)
    np.testing.assert_allclose(res.score[finite], ref[finite], rtol=SPEED_RTOL)


@pytest.mark.parametrize("n_peaks", [1, 3, 10])
def test_peak_rank_weights_give_the_mean_of_top_j_means(n_peaks: int) -> None:
    """For L = 1..n_peaks sorted values, (H_L + n / L - 1) sum q - sum H(r - 1) q_r is n_peaks x eq. 6's mean."""
    _, _, (alpha_n, has_n) = peak_ranks(np.arange(1.0, 4.0), np.array([3.0]), n_peaks)
    q = np.random.default_rng(n_peaks).uniform(10.0, 90.0, n_peaks)
    harm = np.concatenate([[0.0], np.cumsum(1.0 / np.arange(1, n_peaks + 1))])
    for ell in range(1, n_peaks + 1):
        p = q[:ell]
        top_j = np.cumsum(p) / np.arange(1, ell + 1)
        expected = float(np.mean(top_j[np.minimum(np.arange(1, n_peaks + 1), ell) - 1]))
        ours = (alpha_n[ell] * p.sum() - float(harm[:ell] @ p)) / has_n[ell]
        assert expected == pytest.approx(ours, rel=1e-12)


def test_many_peaks_and_shared_f_max_columns_match_batch() -> None:
    """Every local maximum counted (ratio 0, up to (c + 1) / 2 peaks) and f_max values sharing their bins (pad 2, step 0.25 Hz): graph speeds equal the batch estimator's."""
    est = _fitted(
        min_peak_ratio=0.0,
        f_max_range=(15.0, 40.0),
        f_max_step=0.25,
        pad_factor=2,
        interpolate=True,
    )
    cols, mult, _ = peak_ranks(
        np.fft.rfftfreq(2 * W, 1.0 / RATE)[1:81], np.arange(15.0, 40.01, 0.25), 10
    )
    assert (51, 101) == (cols.shape[1], int(mult.sum()))
    graph = export_stick_slip_speed(est)
    rng = np.random.default_rng(5)
    t = np.arange(W) / RATE
    windows = np.stack(
        [
            0.2 * np.sin(2 * np.pi * f * t) + rng.normal(0.0, 0.05, W)
            for f in rng.uniform(12.0, 45.0, 12)
        ]
    )[:, :, None]
    ours = _run(graph, windows)
    ref = np.array(
        [est.speed_from_frequency(est.segment_frequency(w))[0] for w in windows]
    )
    assert np.array_equal(np.isfinite(ref), np.isfinite(ours))
    np.testing.assert_allclose(ours, ref, rtol=SPEED_RTOL, equal_nan=True)
