"""FSR touch-and-slip detector (Gentile et al. 2020): stages, timing, batch == streaming."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit import config_dir
from slipkit.data import Dataset
from slipkit.families.fsr.physics import force_from_voltage
from slipkit.families.fsr.touch_slip import FSRTouchSlip
from slipkit.sim.commands import build_scene

REST_V, PRESSED_V = 4.5, 2.5


@lru_cache(maxsize=1)
def simulated() -> Dataset:
    """Three trials of the fsr_probe_slide scene from its real config."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=fsr_probe_slide"])
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    return build_scene(cfg.scene).simulate(3, seed=3)


def stacked() -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """(X, slip_event labels, segments, per-trial X) of the simulated trials."""
    xs, ys, segs = [], [], []
    for k, tr in enumerate(simulated()):
        xs.append(tr.streams["fsr"][["voltage"]].to_numpy())
        ys.append(tr.streams["truth_contact"]["slip_event"].to_numpy())
        segs.append(np.full(len(xs[-1]), k))
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(segs), xs


def press_then_spikes(n: int = 400, spikes: tuple[int, ...] = (200, 300)) -> np.ndarray:
    """Rest, a press at sample 50 (voltage drops), then sharp releases (rises) at ``spikes``."""
    v = np.full(n, REST_V)
    v[50:] = PRESSED_V
    for s in spikes:
        v[s : s + 5] += 0.2  # a 0.2 V rise for one block: 80 V/s at 2 kHz / 5
    return v[:, None]


@pytest.mark.parametrize("input_", ["voltage", "force"])
def test_batch_equals_streaming_on_simulated_recordings(input_: str) -> None:
    """Scores and decisions of predict (segments) equal the streaming replay per trial."""
    X, y, seg, xs = stacked()
    det = FSRTouchSlip(input=input_).fit(X, y, segments=seg)
    batch = det.decision_function(X, segments=seg)
    for k, x in enumerate(xs):
        scores, dec = det.replay(x)
        np.testing.assert_allclose(batch[seg == k], scores, rtol=1e-12, atol=0)
        assert (batch[seg == k] >= det.threshold_).tolist() == dec.tolist()


def test_the_paper_alpha_separates_simulated_slip_events() -> None:
    """At alpha = 8 V/s every simulated slip event fires and no disturbance does."""
    det = FSRTouchSlip(threshold=8.0)
    det.fit(*stacked()[:2], segments=stacked()[2])
    fired_events, events, fired_dist = 0, 0, 0
    for tr in simulated():
        truth = tr.streams["truth_contact"]
        pred = det.predict(tr.streams["fsr"][["voltage"]].to_numpy()).astype(bool)
        ev = truth["slip_event"].to_numpy() > 0
        starts = np.flatnonzero(np.diff(np.concatenate([[0], ev.astype(int)])) == 1)
        for s in starts:
            events += 1
            fired_events += bool(pred[s : s + 30].any())
        dist = truth["disturbance"].to_numpy() > 0
        fired_dist += int((pred & dist).any())
    assert events == fired_events
    assert 0 == fired_dist


def test_roc_choice_separates_a_synthetic_press_and_release() -> None:
    """Fit on labelled spikes picks an alpha between the press and the release spikes."""
    X = press_then_spikes()
    y = np.zeros(len(X), int)
    for s in (200, 300):
        y[s + 4 : s + 9] = 1  # decided at the spike block's last sample, held one block
    det = FSRTouchSlip().fit(X, y)
    assert 1.0 == det.auc_
    assert y.tolist() == det.predict(X).tolist()
    assert 0.0 < det.threshold_ <= 80.0 + 1e-9


@pytest.mark.parametrize("input_", ["voltage", "force"])
def test_touch_is_not_slip(input_: str) -> None:
    """The press (a falling voltage, a rising force) is a touch, never a slip."""
    X = press_then_spikes(spikes=())
    det = FSRTouchSlip(input=input_, threshold=1e-6).fit(X, np.zeros(len(X), int))
    assert 0 == det.predict(X).sum()
    touch = det.touch(X)
    assert not touch[:50].any()
    assert touch[60:].all()


def test_simulated_touch_is_not_slip() -> None:
    """During each simulated press no alpha > 0 fires; around it alpha = 8 V/s does not."""
    X, y, seg, xs = stacked()
    tiny = FSRTouchSlip(threshold=1e-3).fit(X, y, segments=seg)
    paper = FSRTouchSlip(threshold=8.0).fit(X, y, segments=seg)
    for tr, x in zip(simulated(), xs, strict=True):
        t = tr.streams["fsr"]["t"].to_numpy()
        rise = (t >= 0.3) & (t < 0.31)  # touch at 0.3 s, 10 ms rise
        assert not tiny.predict(x)[rise].any()
        assert not paper.predict(x)[(t > 0.2) & (t < 0.4)].any()
        assert paper.touch(x)[(t > 0.32) & (t < 0.9)].all()
        assert not paper.touch(x)[t < 0.3].any()


def test_no_touch_no_slip() -> None:
    """A recording that starts pressed never sees a touch, so spikes are not slip."""
    X = press_then_spikes()[60:]
    det = FSRTouchSlip(threshold=1.0, polarity="falling").fit(X, np.zeros(len(X), int))
    assert np.isneginf(det.decision_function(X)).all()


def test_block_timing() -> None:
    """First decision at sample 14 (after 10 rest samples); each block's score holds 5 samples."""
    X = press_then_spikes()
    det = FSRTouchSlip(threshold=1.0).fit(X, np.zeros(len(X), int))
    s = det.decision_function(X)
    assert np.isneginf(s[:14]).all()
    spike = 200  # a block boundary: the rise is decided at 204 and held to 208
    assert 80.0 == pytest.approx(s[spike + 4])
    assert 10 == np.count_nonzero(np.isclose(s, 80.0))  # two spikes, 5 samples each
    assert s[spike + 3] < 1.0


def test_force_input_uses_the_calibration() -> None:
    """With input=force the score is -dF/dt of the eq. 6 force (N/s)."""
    X = press_then_spikes()
    det = FSRTouchSlip(input="force", threshold=1.0).fit(X, np.zeros(len(X), int))
    f = force_from_voltage(np.array([PRESSED_V, PRESSED_V + 0.2]))
    expected = -(f[1] - f[0]) * 2000.0 / 5
    assert expected == pytest.approx(det.decision_function(X)[204])


def test_bad_calibration_is_refused() -> None:
    """A calibration without 5 coefficients is a clear error."""
    X = press_then_spikes()
    det = FSRTouchSlip(input="force", calibration=[1.0, 2.0], threshold=1.0)
    with pytest.raises(ValueError, match="5 coefficients"):
        det.fit(X, np.zeros(len(X), int))


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 40),
    level=st.floats(0.0, 5.0),
    input_=st.sampled_from(["voltage", "force"]),
)
def test_constant_and_short_signals_never_fire(
    n: int, level: float, input_: str
) -> None:
    """A constant signal (no touch) and anything shorter than the rest period score -inf."""
    X = np.full((n, 1), level)
    det = FSRTouchSlip(input=input_, threshold=0.0, polarity="falling").fit(
        np.full((20, 1), level), np.zeros(20, int)
    )
    scores, dec = det.replay(X)
    assert np.isneginf(det.decision_function(X)).all()
    assert np.isneginf(scores).all()
    assert not dec.any()


@settings(max_examples=40, deadline=None)
@given(nan_at=st.lists(st.integers(0, 399), max_size=6))
def test_nan_samples_block_decisions_alike_in_batch_and_stream(
    nan_at: list[int],
) -> None:
    """A NaN sample silences its block and the next; batch and streaming still agree."""
    X = press_then_spikes()
    X[nan_at] = np.nan
    det = FSRTouchSlip(threshold=8.0).fit(press_then_spikes(), np.zeros(400, int))
    batch = det.decision_function(X)
    scores, dec = det.replay(X)
    np.testing.assert_array_equal(batch, scores)
    assert (batch >= 8.0).tolist() == dec.tolist()
    for i in nan_at:
        b = i // 5
        assert np.isneginf(batch[5 * b + 4 : 5 * b + 14]).all()
