"""SlipTack onset detectors: the nib's deflection rate (analytic) and its learned logistic form."""

from __future__ import annotations

import numpy as np
import pytest

from slipkit.errors import TrainingDataError
from slipkit.families.sliptack.onset import (
    SlipTackOnset,
    SlipTackOnsetLogistic,
    slope_weights,
)

RATE = 1000.0
SIGMA = 0.01  # mm, the simulated read-out noise


def pull(
    rng: np.random.Generator, *, speed: float, rest: int = 400, n: int = 600
) -> tuple[np.ndarray, np.ndarray]:
    """A stuck nib at rest, then dragged at ``speed`` mm/s from frame ``rest`` (mm; labels)."""
    t = np.arange(n) / RATE
    x = 1.0 + np.where(t >= rest / RATE, speed * (t - rest / RATE), 0.0)
    y = (np.arange(n) >= rest).astype(int)
    return x + rng.normal(0.0, SIGMA, n), y


def drop(rng: np.random.Generator, *, rest: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Fingers opening from frame ``rest - 15`` (the gross deflection falls 3 -> 2 mm,
    tau 20 ms), then the object accelerating at 3.5 m/s^2 from ``rest`` (the nib ramp)."""
    n = rest + 200
    t = np.arange(n) / RATE
    t_open = (rest - 15) / RATE
    gross = np.where(t >= t_open, 2.0 + np.exp(-(t - t_open) / 0.02), 3.0)
    ramp = np.where(t >= rest / RATE, 0.5 * 3500.0 * (t - rest / RATE) ** 2, 0.0)
    y = (np.arange(n) >= rest).astype(int)
    return gross + ramp + rng.normal(0.0, SIGMA, n), y


def stack(
    recs: list[tuple[np.ndarray, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X, y, segments) of recordings."""
    X = np.concatenate([x for x, _ in recs])[:, None]
    y = np.concatenate([lab for _, lab in recs])
    seg = np.concatenate([np.full(len(x), i) for i, (x, _) in enumerate(recs)])
    return X, y, seg


def training(seed: int = 0, n: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pulls at 10-100 mm/s."""
    rng = np.random.default_rng(seed)
    speeds = np.geomspace(10.0, 100.0, n)
    return stack([pull(rng, speed=float(v)) for v in speeds])


def first_alarm(det: SlipTackOnset, x: np.ndarray) -> int:
    """Frame of the first decision ``slip`` (len(x): none)."""
    hits = np.flatnonzero(det.predict(x[:, None]) == 1)
    return int(hits[0]) if len(hits) else len(x)


def test_slope_weights_give_the_line_slope() -> None:
    """x @ slope_weights(n, rate) of a line a + b t is b (per second)."""
    t = np.arange(20) / RATE
    assert 37.5 == pytest.approx(float((2.0 + 37.5 * t) @ slope_weights(20, RATE)))


def test_analytic_detects_pulls_within_a_few_frames() -> None:
    """Fitted on pulls: held-out pulls at 10 and 100 mm/s are declared 1-15 frames
    after their onset and never before it."""
    X, y, seg = training()
    det = SlipTackOnset(window=20).fit(X, y, segments=seg)
    rng = np.random.default_rng(7)
    lags = [first_alarm(det, pull(rng, speed=v)[0]) - 400 for v in (10.0, 100.0)]
    assert (1.0, True, True) == (
        det.sign_,
        all(0 <= lag <= 15 for lag in lags),
        lags[1] <= lags[0],
    )


def test_learned_sign_follows_the_signal() -> None:
    """Pulls whose signal falls give sign -1 and are still detected after the onset."""
    X, y, seg = training()
    det = SlipTackOnset(window=20).fit(-X, y, segments=seg)
    lag = first_alarm(det, -pull(np.random.default_rng(3), speed=30.0)[0]) - 400
    assert (-1.0, True) == (det.sign_, 0 <= lag <= 15)


def test_opening_fingers_do_not_fire_the_rising_direction() -> None:
    """A drop: the falling gross deflection before the onset scores below 0 and the
    accelerating nib ramp is declared after the onset."""
    X, y, seg = training()
    det = SlipTackOnset(window=20).fit(X, y, segments=seg)
    x, _ = drop(np.random.default_rng(5))
    scores = det.decision_function(x[:, None])
    lag = first_alarm(det, x) - 400
    assert (True, True) == (
        bool(np.max(scores[385 + 10 : 400]) < 0.0),
        0 <= lag <= 40,
    )


@pytest.mark.parametrize("cls", [SlipTackOnset, SlipTackOnsetLogistic])
def test_stream_agrees_with_batch(cls: type[SlipTackOnset]) -> None:
    """Frame by frame (replay) gives the batch scores exactly, warm-up -inf included."""
    X, y, seg = training()
    det = cls(window=20).fit(X, y, segments=seg)
    x, _ = pull(np.random.default_rng(9), speed=20.0, n=500)
    batch = det.decision_function(x[:, None])
    streamed, _ = det.replay(x[:, None])
    assert (True, True) == (
        bool(np.array_equal(np.isinf(batch), np.isinf(streamed))),
        bool(np.allclose(batch[np.isfinite(batch)], streamed[np.isfinite(streamed)])),
    )


def test_nan_frame_scores_minus_inf_while_in_the_window() -> None:
    """A NaN frame makes every window holding it -inf (cannot decide), not a number."""
    X, y, seg = training()
    det = SlipTackOnset(window=10).fit(X, y, segments=seg)
    x, _ = pull(np.random.default_rng(2), speed=50.0)
    x[300] = np.nan
    s = det.decision_function(x[:, None])
    assert (True, True) == (
        bool(np.all(np.isneginf(s[300:310]))),
        bool(np.isfinite(s[310])),
    )


def test_logistic_logit_is_its_features_linear_model() -> None:
    """The learned score is coef_ . features + intercept_ of the window's slopes and bend."""
    X, y, seg = training()
    det = SlipTackOnsetLogistic(window=20).fit(X, y, segments=seg)
    x, _ = pull(np.random.default_rng(4), speed=30.0, n=450)
    window = x[-20:]
    expected = float(window @ det.feature_matrix() @ det.coef_ + det.intercept_)
    assert expected == pytest.approx(float(det.decision_function(x[:, None])[-1]))


def test_logistic_detects_pulls_after_their_onset() -> None:
    """Fitted on pulls: held-out pulls at 10 and 100 mm/s are declared 0-20 frames after the onset."""
    X, y, seg = training()
    det = SlipTackOnsetLogistic(window=20).fit(X, y, segments=seg)
    rng = np.random.default_rng(11)
    lags = [first_alarm(det, pull(rng, speed=v)[0]) - 400 for v in (10.0, 100.0)]
    assert True == all(0 <= lag <= 20 for lag in lags)  # noqa: E712


def test_learned_direction_without_slip_is_refused() -> None:
    """direction='learned' on recordings without slip frames: TrainingDataError naming the fix."""
    x, _ = pull(np.random.default_rng(1), speed=10.0)
    with pytest.raises(TrainingDataError, match="direction 'learned'"):
        SlipTackOnset(threshold=5.0).fit(x[:, None], np.zeros(len(x), int))
