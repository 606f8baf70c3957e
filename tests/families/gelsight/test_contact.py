"""Contact-phase detectors: arming early, a horizon, fingertips agreeing, the sign."""

from __future__ import annotations

import numpy as np
import pytest

from slipkit.errors import SlipkitError
from slipkit.families.gelsight.detectors import PinMotionDetector
from slipkit.families.gelsight.report import Candidate, evaluate


def _field(scale: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """A 5x5 pin grid (pitch 30 px) scaled about its centre by ``scale[t]`` and moved
    along x by ``shift[t]``: rows ``x_0..x_24, y_0..y_24``."""
    xs, ys = np.meshgrid(np.arange(5) * 30.0, np.arange(5) * 30.0)
    p = np.column_stack([xs.ravel(), ys.ravel()])
    c = p.mean(axis=0)
    pts = c + (p - c)[None] * scale[:, None, None]
    pts[..., 0] += shift[:, None]
    return np.concatenate([pts[..., 0], pts[..., 1]], axis=1)


def _trial(rng: np.random.Generator, slip: bool, n: int = 160) -> dict:
    """Slip: the field contracts by 2 % over frames 4-8 (the opening jump), then
    rests; wiggle: a still opening, then from frame 80 a shake that spreads and
    contracts the field by up to 5 %."""
    t = np.arange(n, dtype=np.float64)
    if slip:
        scale = 1 - 0.02 * np.clip((t - 4) / 4, 0, 1)
        shift = np.zeros(n)
    else:
        on = t >= 80
        scale = 1 + on * 0.05 * np.sin(t / 3)
        shift = on * 5.0 * np.sin(t / 3)
    noise = rng.normal(0, 0.03, (n, 50))
    f = _field(scale, shift)
    return {"camera_0": f + noise, "camera_2": f + noise[:, ::-1]}


def _data() -> tuple[list, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    trials, y, g = [], [], []
    for obj in range(6):
        for slip in (True, False, True, False):
            trials.append(_trial(rng, slip))
            y.append(int(slip))
            g.append(f"o{obj}")
    return trials, np.array(y), np.array(g)


def _ba(make) -> float:
    trials, y, g = _data()
    r = evaluate(Candidate("d", (("", make),)), trials, y, g, seed=0, outer=3, inner=2)
    return float(r["balanced_accuracy"])


def test_armed_early_and_watching_the_contact_phase_the_opening_jump_is_caught() -> (
    None
):
    def contact(**kw):
        return lambda: PinMotionDetector(quantity="divergence", window=50, **kw)

    # armed late, the reference misses the jump; the late shake then fires on wiggles
    assert _ba(contact(arm=12)) <= 0.6
    # armed at frame 3 with no horizon: the jump is read, but so is the late shake
    assert _ba(contact(arm=3)) <= 0.6
    # watching the 50 frames after arming: jumps fire, the late shakes are not read
    assert _ba(contact(arm=3, horizon=50)) == 1.0


def test_the_horizon_blanks_scores_after_it_and_contraction_keeps_the_sign() -> None:
    t = np.arange(120.0)
    shrink = {"camera_0": _field(1 - 0.001 * t, np.zeros(120))}
    spread = {"camera_0": _field(1 + 0.001 * t, np.zeros(120))}
    det = PinMotionDetector(quantity="contraction", arm=3, horizon=40)
    s = det.frame_scores(shrink)
    assert np.isnan(s[:3]).all()
    assert np.isnan(s[43:]).all()
    assert np.isfinite(s[10:43]).all()
    assert det.trial_score(shrink) > 0 > det.trial_score(spread)
    both = PinMotionDetector(quantity="divergence", arm=3)
    assert both.trial_score(shrink) == pytest.approx(both.trial_score(spread), rel=0.1)


def test_fingertips_must_agree_when_asked() -> None:
    t = np.arange(60.0)
    still = _field(np.ones(60), np.zeros(60))
    moved = _field(1 - 0.001 * t, np.zeros(60))
    one = {"camera_0": moved, "camera_2": still}
    two = {"camera_0": moved, "camera_2": moved}
    lone = PinMotionDetector(quantity="divergence", arm=3, fingers="max")
    agree = PinMotionDetector(quantity="divergence", arm=3, fingers="min")
    assert lone.trial_score(one) == pytest.approx(lone.trial_score(two))
    assert agree.trial_score(one) < 1e-6 < agree.trial_score(two)
    first = PinMotionDetector(quantity="divergence", arm=3, fingers="first")
    assert first.trial_score(one) == pytest.approx(lone.trial_score(one))
    assert first.trial_score({"camera_0": still, "camera_2": moved}) < 1e-6


@pytest.mark.parametrize(
    "kw", [{"horizon": 0}, {"fingers": "mean"}, {"quantity": "speed"}]
)
def test_bad_settings_are_refused_in_one_line(kw: dict) -> None:
    with pytest.raises(SlipkitError, match=next(iter(kw))):
        PinMotionDetector(**kw)


def test_contact_candidates_stay_armed_at_contact_whatever_the_report_arm() -> None:
    from slipkit.families.gelsight.report import CONTACT_ARMS, candidates

    cands = {c.name: c for c in candidates(0, arm=50)}
    for name in ("divergence_contact", "contact_motion", "contact_logistic"):
        arms = {factory().arm for _, factory in cands[name].settings}
        assert arms <= set(CONTACT_ARMS)
    assert {f().arm for _, f in cands["pin_motion"].settings} == {50}
    horizons = {f().horizon for _, f in cands["contact_motion"].settings}
    assert None in horizons
    assert len(horizons) > 1


def test_the_learned_contact_detector_watches_only_its_horizon() -> None:
    from slipkit.families.gelsight.report import candidates

    cands = {c.name: c for c in candidates(0)}
    dets = [f() for _, f in cands["contact_logistic"].settings]
    assert {d.horizon for d in dets} == {100, 200}
    rng = np.random.default_rng(0)
    frames = np.cumsum(rng.normal(0, 0.3, (400, 60)), axis=0) + np.tile(
        np.r_[np.arange(30) % 6 * 30.0, np.arange(30) // 6 * 30.0], (400, 1)
    )
    trial = {"camera_0": frames}
    det = dets[0].fit([trial, {"camera_0": frames[::-1].copy()}], [1, 0])
    s = det.frame_scores(trial)
    assert np.isfinite(s[det.arm + 10 : det.arm + det.horizon]).all()
    assert np.isnan(s[det.arm + det.horizon :]).all()
