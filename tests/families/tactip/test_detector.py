"""The analytic TacTip detector (pooled pin motion) and the pooled pin features."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit.families.tactip.detector import PinMotionDetector
from slipkit.features.pins import POOLED_NAMES, pooled_features


def stretch_then_snap(
    n_pins: int, *, n: int = 80, onset: int = 50, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Pins (n, 2 N) that creep along -y until ``onset`` then snap back along +y, with jitter."""
    rng = np.random.default_rng(seed)
    rest = rng.uniform(-5, 5, size=(2, n_pins))
    vy = np.where(np.arange(n) < onset, -0.01, 0.0)
    vy[onset : onset + 4] = 0.05
    y_shift = np.cumsum(vy)
    frames = np.empty((n, 2 * n_pins))
    frames[:, :n_pins] = rest[0] + rng.normal(0, 0.005, (n, n_pins))
    frames[:, n_pins:] = rest[1] + y_shift[:, None] + rng.normal(0, 0.005, (n, n_pins))
    labels = (np.arange(n) >= onset).astype(int)
    return frames, labels


def test_reversal_fires_at_the_snap_back_not_during_the_stretch() -> None:
    """A steady stretch scores below the threshold; the snap-back against it crosses it."""
    X, y = stretch_then_snap(37)
    det = PinMotionDetector(threshold=0.02).fit(X, y)
    pred = det.predict(X)
    assert 0 == int(pred[:50].sum())
    assert 51 == int(np.flatnonzero(pred)[0])  # two consecutive frames: onset + 1


def test_coherent_score_also_fires_on_the_stretch() -> None:
    """The |mean velocity| score sees an aligned stretch as motion (what reversal avoids)."""
    X, y = stretch_then_snap(37)
    det = PinMotionDetector(score="coherent", threshold=0.005).fit(X, y)
    assert det.predict(X)[5:50].all()


def test_fitted_on_one_pin_count_scores_another() -> None:
    """A detector fitted on 127 pins scores 331-pin frames with the same decisions' timing."""
    X127, y127 = stretch_then_snap(127)
    X331, _ = stretch_then_snap(331, seed=1)
    det = PinMotionDetector().fit(X127, y127)
    assert 127 == det.n_pins_in_
    assert 51 == int(np.flatnonzero(det.predict(X331))[0])


def test_batch_equals_streaming_with_missing_pins() -> None:
    """Batch and frame-by-frame scores agree, NaN pins and all, over two recordings."""
    X, y = stretch_then_snap(19)
    X[10, 3] = np.nan
    X[30, [2, 21]] = np.nan
    X[40, :] = np.nan  # every pin lost in one frame: no decision there
    det = PinMotionDetector(lookback=5, gap=2).fit(
        np.vstack([X, X]), np.r_[y, y], segments=np.r_[np.zeros(80), np.ones(80)]
    )
    batch = det.decision_function(X)
    stream, _ = det.replay(X)
    np.testing.assert_allclose(stream, batch, rtol=0, atol=1e-15)
    assert np.isneginf(batch[40])


def test_odd_channel_count_is_refused() -> None:
    """Pin frames are x and y blocks: an odd number of channels is an error naming it."""
    with pytest.raises(ValueError, match=r"even number of channels\); X has 5"):
        PinMotionDetector(threshold=0.0).fit(np.zeros((30, 5)), np.zeros(30))


def test_pooled_features_ignore_missing_pins() -> None:
    """Pooled statistics count only pins with a velocity (dr > 0); all-aligned pins give R = 1."""
    dr = np.array([[0.1, 0.3, 0.0, 0.2]])
    theta = np.array([[0.5, 0.5, 2.0, 0.5]])
    out = pooled_features(np.hstack([dr, theta]))[0]
    expected = {
        "speed_mean": 0.2,
        "speed_rms": np.sqrt((0.01 + 0.09 + 0.04) / 3),
        "speed_max": 0.3,
        "resultant": 1.0,
        "velocity_mean": 0.2,
        "alignment": 0.2,
    }
    np.testing.assert_allclose(out, [expected[k] for k in POOLED_NAMES], atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(
    n_pins=st.integers(1, 50),
    angle=st.floats(-np.pi, np.pi),
    seed=st.integers(0, 1000),
)
def test_pooled_features_are_rotation_invariant(
    n_pins: int, angle: float, seed: int
) -> None:
    """Rotating every pin direction by one angle changes no pooled statistic."""
    rng = np.random.default_rng(seed)
    dr = rng.uniform(0, 1, (3, n_pins))
    theta = rng.uniform(-np.pi, np.pi, (3, n_pins))
    a = pooled_features(np.hstack([dr, theta]))
    b = pooled_features(np.hstack([dr, theta + angle]))
    np.testing.assert_allclose(b, a, atol=1e-9)


def _simulate(scene: str, n: int, seed: int):
    from hydra import compose, initialize_config_dir

    from slipkit import config_dir
    from slipkit.sim.commands import build_scene

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={scene}"])
    return build_scene(cfg.scene).simulate(n, seed=seed)


def test_fitted_on_the_127_pin_hard_scene_it_detects_331_pin_slips_on_time() -> None:
    """Threshold from the 127-pin hard scene's event ROC; on 331 pins at 60 FPS every slip
    fires within 2 frames of its onset velocity frame and no trial fires before it."""
    from slipkit.train.tasks.detection import StreamDetection

    task = StreamDetection(stream="pins", roc_unit="event", negative_window_s=0.05)
    det = PinMotionDetector()
    task._fit_one(
        det, task.recordings(_simulate("tactip_gravity_drop_hard", 10, 0), "pins", None)
    )
    rec = task.recordings(
        _simulate("tactip_gravity_drop_hard_331", 10, 1), "pins", None
    )
    pred = det.predict(rec.X, segments=rec.segments) > 0
    delays = []
    for k, (a, b) in enumerate(rec.bounds()):
        onset_frame = int(np.searchsorted(rec.t[a:b], rec.onset_s[k])) - 1
        fired = np.flatnonzero(pred[a + 1 : b])  # sample j + 1 ends velocity frame j
        delays.append(int(fired[0]) - onset_frame if len(fired) else None)
    assert [True] * 10 == [d is not None and 0 <= d <= 2 for d in delays]


def test_onset_calibration_puts_the_threshold_mid_gap() -> None:
    """With separable trials the free threshold is halfway between the largest pre-onset score
    and the smallest on-time slip score, not at the edge of either."""
    parts = [stretch_then_snap(31, seed=s) for s in range(3)]
    X = np.vstack([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    seg = np.repeat(np.arange(3), 80)
    det = PinMotionDetector().fit(X, y, segments=seg)
    units, best = det.onset_units(y, det.decision_function(X, segments=seg), seg)
    before, on_time = best[units == 0].max(), best[units == 1].min()
    assert before < on_time
    assert pytest.approx(0.5 * (before + on_time), rel=1e-12) == det.threshold_
