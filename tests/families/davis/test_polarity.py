"""DAVIS event-polarity detector (Rigi et al. 2018): filtering, rule, streaming, bin scoring."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit import config_dir
from slipkit.data import Dataset
from slipkit.families.davis.polarity import (
    NONE,
    SLIP,
    VIBRATION,
    DavisPolarity,
    bin_scores,
    classify,
    clean_frame,
    contact_end,
    prf,
)
from slipkit.sim.commands import build_scene

SHAPE = (180, 190)


@lru_cache(maxsize=1)
def simulated() -> Dataset:
    """Two trials of the davis_release scene from its real config."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=davis_release"])
    GlobalHydra.instance().clear()
    return build_scene(cfg.scene).simulate(2, seed=5)


def block_events(t: float, x0: int, y0: int, side: int, polarity: int) -> np.ndarray:
    """Events of a filled ``side`` x ``side`` square at time ``t``."""
    xs, ys = np.meshgrid(np.arange(x0, x0 + side), np.arange(y0, y0 + side))
    n = xs.size
    return np.column_stack(
        [np.full(n, t), xs.ravel(), ys.ravel(), np.full(n, polarity)]
    )


def fitted(**kw: object) -> DavisPolarity:
    return DavisPolarity(**kw).fit(np.empty((0, 4)))  # type: ignore[arg-type]


# -- one frame -----------------------------------------------------------------------------
@pytest.mark.parametrize("shape", ["square", "lines"])
def test_opening_removes_isolated_noise_events(shape: str) -> None:
    """Lone pixels vanish under the opening; a 6 x 6 contact region survives untouched."""
    img = np.zeros(SHAPE, dtype=bool)
    img[50:56, 60:66] = True
    rng = np.random.default_rng(0)
    ys, xs = rng.integers(100, 180, 30), rng.integers(100, 190, 30)
    lone = np.zeros(SHAPE, dtype=bool)
    lone[ys[::2] // 2 * 2, xs[::2] // 2 * 2] = True  # even coordinates: never adjacent
    out = clean_frame(
        img | lone, opening_px=2, closing_px=0, min_area_px=0, opening_shape=shape
    )
    np.testing.assert_array_equal(img, out)


def test_square_opening_erases_a_one_pixel_edge_but_lines_keep_it() -> None:
    """A 1-px strip (a slow release edge) is erased by a 2x2 square, kept by the lines."""
    img = np.zeros(SHAPE, dtype=bool)
    img[40, 20:60] = True
    square = clean_frame(img, opening_px=2, closing_px=0, min_area_px=0)
    lines = clean_frame(
        img, opening_px=2, closing_px=0, min_area_px=0, opening_shape="lines"
    )
    assert 0 == square.sum()
    np.testing.assert_array_equal(img, lines)


@pytest.mark.parametrize(("size", "kept"), [(7, 0), (8, 8), (9, 9)])
def test_area_filter_threshold(size: int, kept: int) -> None:
    """Regions below min_area_px (8) are dropped, regions at or above it kept."""
    img = np.zeros(SHAPE, dtype=bool)
    img[10, 10 : 10 + size] = True
    out = clean_frame(img, opening_px=0, closing_px=0, min_area_px=8)
    assert kept == out.sum()


def test_area_filter_joins_diagonal_neighbours() -> None:
    """8-connectivity: a diagonal line of 8 pixels is one region and is kept."""
    img = np.zeros(SHAPE, dtype=bool)
    img[np.arange(8) + 20, np.arange(8) + 30] = True
    assert 8 == clean_frame(img, opening_px=0, closing_px=0, min_area_px=8).sum()


def test_closing_fills_a_gap_inside_the_frame_only() -> None:
    """Closing fills a one-pixel hole and adds nothing outside the region's box."""
    img = np.zeros(SHAPE, dtype=bool)
    img[0:5, 0:5] = True
    img[2, 2] = False
    out = clean_frame(img, opening_px=0, closing_px=3, min_area_px=0)
    expected = np.zeros(SHAPE, dtype=bool)
    expected[0:5, 0:5] = True
    np.testing.assert_array_equal(expected, out)


def test_slip_vibration_rule() -> None:
    """Incident when positive area > 0: slip if pos >= neg, vibration if neg > pos."""
    pos = np.array([0, 0, 5, 5, 5])
    neg = np.array([0, 9, 5, 4, 6])
    np.testing.assert_array_equal(
        [NONE, NONE, SLIP, SLIP, VIBRATION], classify(pos, neg)
    )


def test_frames_classify_hand_made_events() -> None:
    """Frame 0: negative patch only; frame 1: bigger positive patch (slip); frame 2:
    positive patch smaller than a negative one (vibration)."""
    ev = np.vstack(
        [
            block_events(0.001, 10, 10, 6, -1),
            block_events(0.012, 10, 10, 5, +1),
            block_events(0.013, 40, 40, 3, -1),
            block_events(0.021, 10, 10, 3, +1),
            block_events(0.022, 60, 60, 5, -1),
        ]
    )
    det = fitted(opening_px=2, closing_px=3)
    frames = det.frames(ev)
    assert [0, 1, 2] == frames["frame"].tolist()
    assert [NONE, SLIP, VIBRATION] == frames["incident"].tolist()
    assert [0, 25, 9] == frames["pos_area_px"].tolist()
    assert [36, 9, 25] == frames["neg_area_px"].tolist()


def test_predict_gives_each_event_its_frames_decision() -> None:
    """predict is per event: the events of the slip frame are 1, the others 0."""
    ev = np.vstack(
        [block_events(0.001, 10, 10, 6, -1), block_events(0.012, 10, 10, 5, +1)]
    )
    pred = fitted().predict(ev)
    np.testing.assert_array_equal(np.r_[np.zeros(36), np.ones(25)], pred)


def test_stress_map_accumulates_negative_regions() -> None:
    """The same negative patch in two frames counts 2 per pixel in the stress map."""
    ev = np.vstack(
        [block_events(0.001, 10, 10, 4, -1), block_events(0.011, 10, 10, 4, -1)]
    )
    stress = fitted().stress_map(ev)
    assert 2.0 == stress.max()
    assert 16 == (stress == 2).sum()


# -- streaming ------------------------------------------------------------------------------
def test_batch_equals_streaming_on_a_simulated_trial() -> None:
    """Pushing the events in random chunks gives the batch per-frame table."""
    trial = next(iter(simulated()))
    ev = trial.streams["events"][["t", "x", "y", "polarity"]].to_numpy(np.float64)
    det = fitted()
    batch = det.frames(ev)
    rng = np.random.default_rng(1)
    cuts = np.sort(rng.choice(len(ev), 40, replace=False))
    results = det.stream().feed(np.split(ev, cuts))
    streamed = pd.DataFrame([r.__dict__ for r in results])
    cols = ["frame", "pos_area_px", "neg_area_px", "incident"]
    pd.testing.assert_frame_equal(batch[cols], streamed[cols])
    state = det.stream()
    state.feed([ev])
    np.testing.assert_array_equal(det.stress_map(ev), state.stress_map)


def test_update_frame_takes_one_frame_and_refuses_others() -> None:
    """update_frame classifies one frame; events of a later frame are refused."""
    state = fitted().stream()
    r = state.update_frame(block_events(0.002, 10, 10, 5, +1))
    assert SLIP == r.incident
    with pytest.raises(ValueError, match="frame 1"):
        state.update_frame(block_events(0.035, 10, 10, 5, +1))


def test_out_of_order_events_are_refused() -> None:
    """Events must come in time order (batch and stream)."""
    ev = np.vstack([block_events(0.02, 1, 1, 2, 1), block_events(0.01, 1, 1, 2, 1)])
    with pytest.raises(ValueError, match="time order"):
        fitted().frames(ev)
    with pytest.raises(ValueError, match="time order"):
        fitted().stream().push(ev)


@pytest.mark.parametrize(
    ("row", "match"),
    [([0.0, 190, 0, 1], "x"), ([0.0, 0, -1, 1], "y"), ([0.0, 0, 0, 0], "polarity")],
)
def test_bad_events_are_named(row: list[float], match: str) -> None:
    """Pixels outside the array and polarity other than +-1 get a message naming them."""
    with pytest.raises(ValueError, match=match):
        fitted().frames(np.array([row]))


@settings(max_examples=20, deadline=None)
@given(
    n=st.integers(0, 1),
    t=st.floats(0.0, 1.0),
    x=st.integers(0, 189),
    y=st.integers(0, 179),
    p=st.sampled_from([-1, 1]),
)
def test_zero_or_one_event_never_slips(
    n: int, t: float, x: int, y: int, p: int
) -> None:
    """No events, or a single one, cannot make a region of 8 px: no slip, batch or stream."""
    ev = np.array([[t, x, y, p]] * n, dtype=np.float64).reshape(n, 4)
    det = fitted()
    frames = det.frames(ev)
    assert 0 == int(frames["slip"].sum())
    assert 0 == int(det.predict(ev).sum())
    assert all(not r.slip for r in det.stream().feed([ev]))


# -- scoring ---------------------------------------------------------------------------------
def frames_table(
    slip_frames: list[int], n: int = 20, frame_s: float = 0.01
) -> pd.DataFrame:
    k = np.arange(n)
    return pd.DataFrame(
        {
            "t_start_s": k * frame_s,
            "t_end_s": (k + 1) * frame_s,
            "slip": np.isin(k, slip_frames),
        }
    )


def test_bin_scoring_on_a_hand_made_case() -> None:
    """Slip from 0.105 s to 0.165 s: bins 5-8 are truth. Slip frames 3 (FP bin 1), 11 and
    12 (bins 5, 6: TP) leave bins 7 and 8 FN; the latency is 0.12 - 0.105 s."""
    s = bin_scores(
        frames_table([3, 11, 12]), onset_s=0.105, end_s=0.165, duration_s=0.2
    )
    assert (2, 1, 2) == (s["tp"], s["fp"], s["fn"])
    assert 0.015 == pytest.approx(s["latency_s"])
    assert {"precision": 2 / 3, "sensitivity": 0.5, "f1": 4 / 7} == pytest.approx(
        prf(2, 1, 2)
    )


def test_undetected_slip_has_no_latency() -> None:
    """No slip frame: all truth bins are FN and the latency is NaN."""
    s = bin_scores(frames_table([]), onset_s=0.05, end_s=0.09, duration_s=0.2)
    assert (0, 0, 3) == (s["tp"], s["fp"], s["fn"])
    assert np.isnan(s["latency_s"])


def test_contact_end_is_the_first_zero_area_after_onset() -> None:
    """Slip ends at the first truth frame without contact after the onset."""
    t = np.arange(10) * 0.001
    area = np.array([0, 5, 9, 9, 8, 6, 3, 0, 0, 0])
    assert 0.007 == contact_end(t, area, 0.004)


def test_simulated_release_is_detected() -> None:
    """On simulated releases the detector finds slip soon after the onset (< 50 ms)."""
    det = fitted()
    for trial in simulated():
        frames = det.frames(trial.streams["events"])
        truth = trial.streams["truth_contact"]
        onset = trial.labels["slip_onset_s"]
        end = contact_end(truth["t"], truth["area_px"], onset)
        s = bin_scores(
            frames, onset_s=onset, end_s=end, duration_s=float(truth["t"].iloc[-1])
        )
        assert s["latency_s"] < 0.05
        assert s["tp"] > s["fn"]
