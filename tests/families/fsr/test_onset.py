"""FSR slip onset detectors: a ringing release is slip 2 ms later, a knock's edge never is."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from tests.baselines.test_conventions import fsr_trials
from tests.baselines.test_conventions import stack as generator_stack

from slipkit import config_dir
from slipkit.errors import SlipkitError
from slipkit.families.fsr.onset import FSROnset, FSROnsetLogistic, onset_matrix
from slipkit.families.fsr.touch_slip import PolarityWarning
from slipkit.sim.commands import build_scene

RATE = 2000.0
PRESS_AT = 100  # sample of the press (after a 50 ms rest)


def _held(n: int = 1200, rest: float = 4.5, pressed: float = 3.0) -> np.ndarray:
    """Falling wiring: 4.5 V at rest, pressed to 3.0 V over 10 ms from sample 100."""
    v = np.full(n, rest)
    ramp = np.clip((np.arange(n) - PRESS_AT) / 20.0, 0.0, 1.0)
    return v - (rest - pressed) * ramp


def _slip(v: np.ndarray, at: int, amp: float, ring_hz: float = 150.0) -> np.ndarray:
    """A stick-slip release at sample ``at``: the voltage jumps by ``amp`` and rings back."""
    tau = (np.arange(len(v)) - at) / RATE
    on = tau >= 0
    out = v.copy()
    out[on] += amp * np.exp(-tau[on] / 0.003) * np.cos(2 * np.pi * ring_hz * tau[on])
    return out


def _knock(
    v: np.ndarray, at: int, amp: float, rise_s: float, dur_s: float
) -> np.ndarray:
    """A knock as the simulator's: raised-cosine edges of ``rise_s``, ``dur_s`` long."""
    t = (np.arange(len(v)) - at) / RATE
    r = min(rise_s, dur_s / 2)
    inside = (t >= 0) & (t < dur_s)
    edge = np.clip(np.minimum(t, dur_s - t) / r, 0.0, 1.0)
    out = v.copy()
    out[inside] += amp * 0.5 * (1.0 - np.cos(np.pi * edge[inside]))
    return out


def _fitted(cls: type[FSROnset] = FSROnset, **params: object) -> FSROnset:
    """Fitted on one held recording with one labelled slip (polarity: falling)."""
    v = _slip(_held(), 700, 0.1)
    y = np.zeros(len(v), int)
    y[700:718] = 1
    return cls(polarity="falling", **params).fit(v[:, None], y)  # type: ignore[arg-type]


def test_a_ringing_release_is_slip_rebound_s_after_it() -> None:
    """A 0.1 V one-sample release at 700 scores its size (V) at 704, nothing before."""
    det = _fitted(threshold=0.05)
    s = det.decision_function(_slip(_held(), 700, 0.1)[:, None])
    hits = np.flatnonzero(s >= 0.05)
    assert (704, True) == (int(hits[0]), bool(abs(s[704] - 0.1) < 1e-12))


KNOCKS = [  # (edge, duration) s: edges 1-5 ms, 5-50 ms long, a plateau of >= 1 ms
    (0.001, 0.005),
    (0.002, 0.005),
    (0.0025, 0.006),
    (0.001, 0.05),
    (0.005, 0.02),
    (0.005, 0.05),
]


@pytest.mark.parametrize(("rise_s", "dur_s"), KNOCKS)
@pytest.mark.parametrize("amp", [0.5, -0.5])
def test_a_knock_never_scores(rise_s: float, dur_s: float, amp: float) -> None:
    """Knocks of either sign, 1-5 ms edges, 5-50 ms long, 5x a slip: no score at all.

    (A knock whose edges meet, a triangle, can pass at some sample phases:
    docs/families/fsr.md, "Onset detectors".)"""
    det = _fitted(threshold=0.05)
    s = det.decision_function(_knock(_held(), 700, amp, rise_s, dur_s)[:, None])
    assert 0 == int(np.isfinite(s).sum())


def test_untouched_and_rest_samples_never_score() -> None:
    """A release before the press (the FSR untouched) scores -inf; so does the rest period."""
    det = _fitted(threshold=0.05)
    v = _slip(_held(), 50, 0.1)  # before the press at 100
    s = det.decision_function(v[:, None])
    assert 0 == int(np.isfinite(s[:100]).sum())


@pytest.mark.parametrize("cls", [FSROnset, FSROnsetLogistic])
def test_stream_equals_batch_on_mixed_wirings(cls: type[FSROnset]) -> None:
    """Per-recording polarity (both wirings): the sample-by-sample scores equal the batch ones."""
    rng = np.random.default_rng(3)
    recs, ys = [], []
    for k, wiring in enumerate(["falling", "rising", "falling"]):
        v = _slip(_held(), 600 + 40 * k, 0.08) + rng.normal(0, 2e-3, 1200)
        v = _knock(v, 900, 0.4, 0.002, 0.02)
        if wiring == "rising":
            v = 5.0 - v
        y = np.zeros(len(v), int)
        y[600 + 40 * k : 618 + 40 * k] = 1
        recs.append(v)
        ys.append(y)
    X = np.concatenate(recs)[:, None]
    seg = np.repeat(np.arange(3), 1200)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PolarityWarning)
        det = cls().fit(X, np.concatenate(ys), segments=seg)
    batch = det.decision_function(recs[1][:, None])
    stream = det.stream()
    live = np.array([stream.update([x])[0] for x in recs[1]])
    finite = np.isfinite(batch)
    assert ("per_recording", True, True) == (
        det.polarity_,
        bool(np.array_equal(finite, np.isfinite(live))),
        bool(np.allclose(batch[finite], live[finite], rtol=1e-12, atol=1e-12)),
    )


def test_onset_matrix_columns_are_the_named_differences() -> None:
    """Columns on a window: E, last step, fall back, minus the rises after and before, the press."""
    s = np.array(
        [0.0, 1.0, 3.0, 4.0, 9.0, 20.0, 18.0, 15.0]
    )  # lead 2, edge 2, rebound 3
    cols = s @ onset_matrix(2, 2, 3)  # the release ends at s[4] = 9, decided at s[7]
    assert [6.0, 5.0, -6.0, -11.0, -9.0, -6.0, -1.0, -2.0, -15.0] == cols.tolist()


def test_training_data_without_a_touch_is_refused_naming_the_detector() -> None:
    """polarity=auto with never-pressed recordings: a SlipkitError naming FSROnset."""
    X = np.full((400, 1), 4.5) + np.random.default_rng(0).normal(0, 1e-3, (400, 1))
    with pytest.raises(SlipkitError, match=r"^FSROnset\(polarity='auto'\)"):
        FSROnset().fit(X, np.zeros(400, int))


def test_learned_detector_without_slip_onsets_is_refused() -> None:
    """No labelled slip: a SlipkitError saying which candidates are missing."""
    v = _slip(_held(), 700, 0.1)
    with pytest.raises(SlipkitError, match=r"0 slip-onset and \d+ other touched"):
        FSROnsetLogistic(polarity="falling").fit(v[:, None], np.zeros(len(v), int))


def test_learned_detector_trains_without_knocks() -> None:
    """No other release of min_step_V in training (no knocks): the weaker touched releases
    are its negatives, and it decides the slip 2 ms after it, nowhere else."""
    rng = np.random.default_rng(5)
    v = _slip(_held(), 700, 0.1) + rng.normal(0, 1e-3, 1200)
    y = np.zeros(len(v), int)
    y[700:718] = 1
    det = FSROnsetLogistic(polarity="falling").fit(v[:, None], y)
    held = _slip(_held(), 800, 0.1) + rng.normal(0, 1e-3, 1200)
    hits = np.flatnonzero(det.decision_function(held[:, None]) >= det.threshold_)
    assert [804] == hits.tolist()


def test_onset_calibration_without_other_scores_halves_the_weakest_slip() -> None:
    """Clean training data (only the 0.1 V slip scores): threshold 0.05 V, not 0.1 V."""
    v = _slip(_held(), 700, 0.1)
    y = np.zeros(len(v), int)
    y[700:718] = 1
    det = FSROnset(polarity="falling").fit(v[:, None], y)
    assert 0.05 == round(det.threshold_, 12)


def test_onset_calibration_puts_the_threshold_mid_gap() -> None:
    """An unlabelled 0.04 V ringing release and a labelled 0.1 V slip: threshold 0.07 V."""
    v = _slip(_slip(_held(), 400, 0.04), 700, 0.1)
    y = np.zeros(len(v), int)
    y[700:718] = 1
    det = FSROnset(polarity="falling").fit(v[:, None], y)
    assert 0.07 == round(det.threshold_, 12)


@pytest.fixture(scope="module")
def hard_trials() -> tuple[np.ndarray, ...]:
    """16 trials of the hard probe slide (knocks, both wirings, 1-10 mV noise): 8 + 8."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=fsr_probe_slide_hard"])
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    scene = build_scene(cfg.scene)
    out = []
    for seed in (11, 12):
        Xs, ys, ds, segs = [], [], [], []
        for k, tr in enumerate(scene.simulate(8, seed)):
            f, truth = tr.streams["fsr"], tr.streams["truth_contact"]
            idx = np.clip(
                np.searchsorted(truth["t"], f["t"], side="right") - 1, 0, len(truth) - 1
            )
            Xs.append(f["voltage"].to_numpy())
            ys.append(truth["slip_event"].to_numpy()[idx] > 0)
            ds.append(truth["disturbance"].to_numpy()[idx] > 0)
            segs.append(np.full(len(f), k))
        out += [
            np.concatenate(Xs)[:, None],
            np.concatenate(ys).astype(int),
            np.concatenate(ds),
            np.concatenate(segs),
        ]
    return tuple(out)


def _runs(flags: np.ndarray, seg: np.ndarray) -> list[tuple[int, int]]:
    edges = np.diff(np.concatenate([[0], flags.astype(int), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    # a run never spans two recordings here (each recording ends at rest)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


@pytest.mark.parametrize(
    ("cls", "found_frac", "max_fired"),
    [(FSROnset, 0.9, 0), (FSROnsetLogistic, 0.99, 2)],
)
def test_hard_scene_slips_found_knocks_ignored(
    cls: type[FSROnset],
    found_frac: float,
    max_fired: int,
    hard_trials: tuple[np.ndarray, ...],
) -> None:
    """Trained on 8 hard trials (seed 11), on 8 others (seed 12, 261 stick-slip events,
    25 knocks and bumps): the analytic detector finds >= 90 % of the events within 5 ms
    of their onset and fires on no disturbance; the learned one >= 99 %, <= 2."""
    X, y, _, seg, Xt, yt, dt, segt = hard_trials
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PolarityWarning)
        det = cls().fit(X, y, segments=seg)
    hit = det.decision_function(Xt, segments=segt) >= det.threshold_
    events = _runs(yt > 0, segt)
    found = sum(bool(hit[a : a + 10].any()) for a, _ in events)
    fired = sum(bool(hit[a : b + 10].any()) for a, b in _runs(dt, segt))
    assert (True, True) == (found >= found_frac * len(events), fired <= max_fired)


def test_independent_generator_slides_found_bumps_ignored() -> None:
    """On tests/baselines/test_conventions.py's generator (linear 0.5-2 ms falls that stay
    down, linear-edged bumps), with a 1.5 ms release, trained on its own 8 slides: all 20
    test slides found, the first within 10 ms in most, at most 2 of its bumps fired."""
    train = fsr_trials(100, 4, polarity="falling", slide=True) + fsr_trials(
        101, 4, polarity="rising", slide=True
    )
    X, y, seg = generator_stack(train)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PolarityWarning)
        det = FSROnset(edge_s=0.0015, rebound_frac=0.15).fit(X, y, segments=seg)
    slides = fsr_trials(400, 10, polarity="rising", slide=True) + fsr_trials(
        401, 10, polarity="falling", slide=True
    )
    bumps = fsr_trials(500, 10, polarity="falling", slide=False)
    delays, fired = [], 0
    for tr in slides + bumps:
        hit = det.decision_function(tr.v[:, None]) >= det.threshold_
        if tr.slide is not None:
            at = np.flatnonzero(hit & (tr.t >= tr.slide[0]))
            delays.append((tr.t[at[0]] - tr.events[0]) * 1e3 if len(at) else np.inf)
        fired += sum(
            bool(hit[(tr.t >= a) & (tr.t < b + 0.005)].any()) for a, b in tr.bumps
        )
    assert (20, True, True) == (
        int(np.isfinite(delays).sum()),
        float(np.median(delays)) <= 10.0,
        fired <= 2,
    )


def test_compare_reads_the_onset_window() -> None:
    """slipkit compare's cost table gives the onset detector its 8-sample window (4 ms), not 1."""
    from slipkit.compare.adapters import _detector_window

    assert (8, 8) == (_detector_window(FSROnset()), FSROnset().window_samples)
