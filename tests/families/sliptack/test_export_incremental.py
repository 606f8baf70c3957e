"""The incremental SlipTack graph: the sliding_spectrum op against the batch spectrum, restarts, the noise gate, parity."""

from __future__ import annotations

import tracemalloc
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d

from slipkit.export.detectors import NO_SCORE, check_detector_parity
from slipkit.export.parity import onnx_session
from slipkit.export.registry import ExportError
from slipkit.families.sliptack.export.detector import (
    SpeedSlipDetector,
    export_speed_slip_detector,
)
from slipkit.families.sliptack.export.speed import export_stick_slip_speed, graph_speeds
from slipkit.families.sliptack.speed import StickSlipSpeed, dominant_frequency
from slipkit.runtime import BundleError
from slipkit.runtime.ops.sliptack import SlidingSpectrum
from slipkit.runtime.preprocessing import Pipeline

RATE = 1000.0
W, S, HOP = 300, 300, 10
#: Power spectrum agreement with numpy's, relative to the window's largest bin.
POWER_RTOL = 1e-9
#: The shipped detector config (configs/detector/sliptack_frequency.yaml) on the
#: closed-loop scenario's 300-frame window.
PARAMS: dict[str, Any] = {
    "rate_hz": RATE,
    "window": W,
    "hop": HOP,
    "detrend_frames": S,
    "f_max_range": (15.0, 100.0),
    "min_peak_ratio": 0.6,
    "harmonics": "fundamental",
    "interpolate": True,
}


def _power(x: NDArray[np.float64], s: int) -> NDArray[np.float64]:
    """The batch estimator's power spectrum of one window (scipy detrend, Hamming, rfft)."""
    resid = x - uniform_filter1d(x, min(s, len(x)), mode="nearest")
    return np.abs(np.fft.rfft(resid * np.hamming(len(x)))) ** 2


def _stick_slip(n: int, freq_hz: float, seed: int) -> NDArray[np.float64]:
    """A sawtooth nib signal (mm) on a drifting offset with read-out noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    saw = 0.05 * ((t * freq_hz) % 1.0)
    drift = 0.3 + 0.002 * np.cumsum(rng.normal(size=n))
    return drift + saw + 0.01 * rng.normal(size=n)


def _still(n: int, seed: int) -> NDArray[np.float64]:
    """A still object: a constant deflection and the scene's read-out noise (0.01 mm)."""
    return 0.4 + 0.01 * np.random.default_rng(seed).normal(size=n)


def _fitted(**params: Any) -> StickSlipSpeed:
    return StickSlipSpeed(**{**PARAMS, **params}).fit(
        np.zeros((1, 1)), np.full(1, np.nan)
    )


@pytest.mark.parametrize(("w", "s"), [(300, 300), (1000, 300), (100, 40)])
def test_sliding_power_equals_batch_spectrum(w: int, s: int) -> None:
    """Per hop over a stream, the op's power spectrum equals numpy's within 1e-9 of the largest bin."""
    x = _stick_slip(3 * w, 37.0, seed=1)
    op = SlidingSpectrum(w, s, HOP, w)
    worst = 0.0
    for end in range(w - 1, len(x), HOP):
        win = x[end - w + 1 : end + 1]
        ref = _power(win, s)
        got = op(win[:, None]).reshape(-1)
        worst = max(worst, float(np.max(np.abs(got - ref)) / ref.max()))
    assert (1, True) == (op.rebuilds, worst < POWER_RTOL)


def test_skipped_window_rebuilds_and_stays_exact() -> None:
    """A window that is not the last one moved by hop (a skipped call) rebuilds the sums, still exact."""
    x = _stick_slip(4 * W, 41.0, seed=2)
    op = SlidingSpectrum(W, S, HOP, W)
    ends = [W - 1, W - 1 + HOP, W - 1 + 5 * HOP, W - 1 + 6 * HOP]
    errs = []
    for end in ends:
        win = x[end - W + 1 : end + 1]
        ref = _power(win, S)
        errs.append(float(np.max(np.abs(op(win[:, None]).ravel() - ref)) / ref.max()))
    assert (2, True) == (op.rebuilds, max(errs) < POWER_RTOL)


def test_nonfinite_sample_gives_nan_then_rebuilds() -> None:
    """A NaN in the new samples makes the spectrum NaN; the next clean window rebuilds and is exact."""
    x = _stick_slip(3 * W, 41.0, seed=3)
    op = SlidingSpectrum(W, S, HOP, W)
    op(x[:W, None])
    bad = x[HOP : W + HOP].copy()
    bad[-1] = np.nan
    nan_out = bool(np.isnan(op(bad[:, None])).all())
    win = x[2 * HOP : W + 2 * HOP]
    ref = _power(win, S)
    err = float(np.max(np.abs(op(win[:, None]).ravel() - ref)) / ref.max())
    assert (True, 2, True) == (nan_out, op.rebuilds, err < POWER_RTOL)


def test_reset_rebuilds_on_the_next_call() -> None:
    """reset() forgets the stream: the next call rebuilds even when it continues the last window."""
    x = _stick_slip(2 * W, 41.0, seed=4)
    op = SlidingSpectrum(W, S, HOP, W)
    op(x[:W, None])
    op.reset()
    op(x[HOP : W + HOP, None])
    assert 1 == op.rebuilds


def test_constant_window_is_a_zero_spectrum() -> None:
    """An exactly constant window gives zeros (the batch estimator's flat window: no peak)."""
    op = SlidingSpectrum(W, S, HOP, W)
    assert 0.0 == float(np.abs(op(np.full((W, 1), 0.7))).max())


def test_steady_calls_hold_no_window_sized_temporary() -> None:
    """Once warm, 100 calls of the op keep no memory and never hold a window-sized array."""
    x = _stick_slip(4 * W, 41.0, seed=5)
    op = SlidingSpectrum(W, S, HOP, W)
    wins = [
        np.ascontiguousarray(x[e - W + 1 : e + 1, None])
        for e in range(W - 1, len(x), HOP)
    ]
    for win in wins[:5]:
        op(win)
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        for win in wins[5:105]:
            op(win)
        current, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert (True, True) == (current - start < 1024, peak - start < W * 8)


def test_off_grid_detrend_is_refused_naming_the_field() -> None:
    """A detrend whose range boundaries miss the hop grid is a BundleError naming preprocessing[0].hop."""
    step = {"op": "sliding_spectrum", "detrend_frames": 33, "hop": 10}
    with pytest.raises(BundleError, match=r"preprocessing\[0\]\.hop"):
        Pipeline([step], (300, 1), "manifest.json")


def test_off_grid_estimator_has_no_incremental_export() -> None:
    """Exporting incrementally with an off-grid detrend raises ExportError naming the grid."""
    with pytest.raises(ExportError, match="hop grid"):
        export_stick_slip_speed(_fitted(detrend_frames=33), incremental=True)


def test_incremental_graph_parity_with_batch_estimator() -> None:
    """On held-out stick-slip recordings the incremental graph's speeds agree with the batch estimator (1e-6 relative)."""
    est = _fitted()
    xs = [_stick_slip(1500, f, seed=10 + k) for k, f in enumerate((22.0, 37.0, 58.0))]
    X = np.concatenate(xs)[:, None]
    seg = np.concatenate([np.full(len(x), k) for k, x in enumerate(xs)])
    det = SpeedSlipDetector(speed=est, threshold=10.0).fit()
    graph = export_speed_slip_detector(det, incremental=True)
    rep = check_detector_parity(det, graph, X, segments=seg)
    assert (True, 1.0, 0, True) == (
        rep["passed"],
        rep["agreement"],
        rep["n_finite_mismatch"],
        rep["max_rel_diff"] < 1e-6,
    )
    assert ("batch", 151) == graph.input_shape
    assert "sliding_spectrum" == graph.preprocessing[0]["op"]


def test_gate_reads_a_still_object_as_no_speed() -> None:
    """With the noise gate a still object has no frequency (NaN) and the graph no score; without it, noise reads as a speed."""
    x = _still(W, seed=6)
    gated = dominant_frequency(x, RATE, **_kw(min_peak_to_mean=20.0))
    open_ = dominant_frequency(x, RATE, **_kw())
    est = _fitted(min_peak_to_mean=20.0)
    graph = export_stick_slip_speed(est, incremental=True)
    pipe = Pipeline(list(graph.preprocessing), (W, 1), "manifest.json")
    power = pipe(x[:, None]).astype(np.float32)
    out = onnx_session(graph).run([graph.score_output], {graph.input_name: power})[0]
    assert (True, True, NO_SCORE) == (
        np.isnan(gated),
        np.isfinite(open_),
        float(out[0]),
    )


def test_gate_keeps_a_stick_slip_frequency() -> None:
    """A stick-slip sawtooth passes the gate: the gated frequency equals the ungated one."""
    x = _stick_slip(W, 37.0, seed=7)
    assert dominant_frequency(x, RATE, **_kw()) == dominant_frequency(
        x, RATE, **_kw(min_peak_to_mean=20.0)
    )


def test_gated_graphs_agree_on_still_and_slipping_windows() -> None:
    """Full and incremental gated graphs give the same speeds (NaN where still) on a still-then-slip recording."""
    est = _fitted(min_peak_to_mean=20.0)
    x = np.concatenate([_still(600, seed=8), _stick_slip(900, 37.0, seed=9)])
    full = export_stick_slip_speed(est)
    inc = export_stick_slip_speed(est, incremental=True)
    pipe = Pipeline(list(inc.preprocessing), (W, 1), "manifest.json")
    ends = np.arange(W - 1, len(x), HOP)
    wins = np.stack([x[e - W + 1 : e + 1, None] for e in ends]).astype(np.float32)
    powers = np.stack(
        [pipe(x[e - W + 1 : e + 1, None]).reshape(-1).copy() for e in ends]
    ).astype(np.float32)
    v_full = graph_speeds(
        onnx_session(full).run([full.score_output], {full.input_name: wins})[0]
    )
    v_inc = graph_speeds(
        onnx_session(inc).run([inc.score_output], {inc.input_name: powers})[0]
    )
    ref = est.predict(x[:, None])[ends]
    still = ends < 600
    assert (True, True) == (
        bool(np.isnan(v_inc[still]).all()),
        bool(np.isfinite(v_inc[ends >= 600 + W]).all()),
    )
    np.testing.assert_array_equal(np.isnan(ref), np.isnan(v_inc))
    np.testing.assert_array_equal(np.isnan(v_full), np.isnan(v_inc))
    both = np.isfinite(v_inc)
    np.testing.assert_allclose(v_inc[both], ref[both], rtol=1e-6)


def _kw(**extra: Any) -> dict[str, Any]:
    keys = (
        "detrend_frames",
        "f_max_range",
        "min_peak_ratio",
        "harmonics",
        "interpolate",
    )
    return {**{k: PARAMS[k] for k in keys}, **extra}


def test_incremental_bundle_loop_decides_as_the_batch_estimator(tmp_path: Any) -> None:
    """slipkit export regression.incremental=true -> a bundle with the sliding_spectrum step whose loop decisions equal the batch estimator's."""
    import json

    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from slipkit import config_dir
    from slipkit.export.commands import export_main
    from slipkit.runtime import StreamLoop, load_bundle
    from slipkit.train.commands import train_main
    from slipkit.train.runs import read_run

    def cfg(name: str, overrides: list[str]) -> Any:
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            out = compose(config_name=name, overrides=overrides)
        GlobalHydra.instance().clear()
        return out

    run, out = tmp_path / "run", tmp_path / "bundle"
    train_main(
        cfg(
            "train",
            [
                "experiment=sliptack_speed",
                "dataset.n_trials=6",
                f"detector.window={W}",
                f"run_dir={run}",
            ],
        )
    )
    export_main(
        cfg(
            "export",
            [
                f"run={run}",
                f"out={out}",
                "choose_session=false",
                "regression.threshold=10.0",
                "regression.incremental=true",
            ],
        )
    )
    raw = json.loads((out / "manifest.json").read_text())
    replay = np.load(out / "replay.npz")
    frames, times = replay["frames"], replay["timestamps"]
    loop = StreamLoop(load_bundle(out))
    for values, ts in zip(frames, times, strict=True):
        loop.step(values, float(ts))
    res = loop.result()
    est = read_run(run).model["*"]
    ref = SpeedSlipDetector(speed=est, threshold=10.0).fit().decision_function(frames)
    ref = ref[res.frame]
    assert ["sliding_spectrum", [1, W // 2 + 1], 1.0] == [
        raw["preprocessing"][0]["op"],
        raw["inputs"][0]["shape"],
        raw["training"]["parity"]["agreement"],
    ]
    np.testing.assert_array_equal(ref >= 10.0, res.slip)
    finite = np.isfinite(ref)
    # the graph reads the power spectrum as float32: the peak interpolation's log
    # powers carry its rounding (the whole-window graph's MatMuls are float32 too)
    np.testing.assert_allclose(res.score[finite], ref[finite], rtol=1e-5)
