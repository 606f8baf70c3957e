"""DAVIS release scene: contact patch, event effects and their signatures, config."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st

from slipkit import config_dir
from slipkit.cli import main as cli_main
from slipkit.data import load_dataset
from slipkit.data.dataset import Trial
from slipkit.families.davis.physics import (
    ContactPatch,
    area_curve,
    incipient_slip_onset,
)
from slipkit.families.davis.scene import DavisRelease
from slipkit.sim.commands import build_scene
from slipkit.sim.core import Scene, SimulationError

SCENE = "davis_release"
CONTACT = {
    "contact_events": {"events_per_pixel": 1, "spacing_s": 1e-4, "latency_s": 1.2e-5}
}
VIBRATION = {
    "vibration_incidents": {
        "rate_hz": 20.0,
        "shift_px": [1.0, 3.0],
        "dilation": [0.0, 0.05],
    }
}
BACKGROUND = {"background_events": {"rate_hz": 2000.0}}


def compose_scene(*overrides: str) -> Scene:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={SCENE}", *overrides])
    return build_scene(cfg.scene)


def scene_with(*effects: dict, **model: object) -> Scene:
    merged = {k: v for e in effects for k, v in e.items()}
    return Scene(SCENE, DavisRelease(**model), merged)  # type: ignore[arg-type]


def phases(scene: Scene, index: int, seed: int) -> ContactPatch:
    """The contact patch (phase times) of trial ``index`` of a run seeded ``seed``."""
    model = scene.model
    assert isinstance(model, DavisRelease)
    return model.patch(model.sample(np.random.default_rng([seed, index])))


def window_areas(
    events: pd.DataFrame, start: float, stop: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per 10 ms window in [start, stop): distinct pixels with positive and negative events."""
    edges = np.arange(start, stop - 0.01 + 1e-12, 0.01)
    pos, neg = [], []
    for lo in edges:
        w = events[(events.t >= lo) & (events.t < lo + 0.01)]
        pos.append(len(w[w.polarity > 0][["x", "y"]].drop_duplicates()))
        neg.append(len(w[w.polarity < 0][["x", "y"]].drop_duplicates()))
    return np.array(pos), np.array(neg)


def events_of(trial: Trial) -> pd.DataFrame:
    return trial.streams["events"]


# -- patch geometry ----------------------------------------------------------------------


def test_area_curve_counts_covered_pixels():
    """The area is the number of pixels covered and not yet uncovered at each time."""
    t = np.array([0.0, 1.0, 2.0, 3.0])
    cover, uncover = np.array([0.5, 1.0, 1.5]), np.array([2.5, 2.5, 3.0])
    np.testing.assert_array_equal([0, 2, 3, 0], area_curve(t, cover, uncover))


def test_onset_is_first_frame_below_the_hold_minimum():
    """Incipient slip starts at the first frame after the hold whose area is below the hold minimum."""
    t = np.arange(10) * 0.1
    area = np.array([0, 5, 9, 8, 9, 9, 8, 8, 7, 0])
    assert 0.8 == pytest.approx(incipient_slip_onset(t, area, (0.2, 0.6)))
    assert math.isnan(incipient_slip_onset(t, np.full(10, 9), (0.2, 0.6)))


@settings(max_examples=30, deadline=None)
@given(
    a=st.floats(5.0, 40.0),
    b=st.floats(5.0, 40.0),
    angle=st.floats(0.0, math.pi),
    release=st.floats(0.0, 2 * math.pi),
)
def test_pixels_are_covered_before_uncovered_and_loss_starts_on_the_release_side(
    a, b, angle, release
):
    """Every pixel is covered during the press and uncovered during the release, the release side first."""
    patch = ContactPatch(95.0, 90.0, a, b, angle, release, 0.1, 0.4, 1.0, 0.5)
    x, y = patch.bbox(1.0, 1.0, 190, 180)
    tc = patch.cover_times(x, y)
    inside = np.isfinite(tc)
    tu = patch.uncover_times(x[inside], y[inside])
    assert np.all((tc[inside] >= 0.1) & (tc[inside] <= 0.5))
    assert np.all((tu >= 1.0) & (tu <= 1.5))
    q = patch.projection(x[inside], y[inside])
    assert np.all(np.diff(tu[np.argsort(-q)]) >= -1e-12)


# -- scene from the real config ------------------------------------------------------------


def test_scene_from_config_has_events_truth_labels_and_groups():
    """The config builds sorted (t, x, y, polarity) events on 190 x 180, 1 kHz truth, onset, object."""
    ds = compose_scene("n_trials=3").simulate(3, seed=0)
    assert {"events": None, "truth_contact": 1000.0} == {
        s: v.rate_hz for s, v in ds.streams.items()
    }
    assert "events" == ds.streams["events"].kind
    assert ("x", "y", "polarity") == ds.streams["events"].channels
    assert ("object",) == ds.groups
    assert ["slip_onset_s"] == list(ds.labels)
    assert set(ds.trials["object"]) <= {"disc_r3mm", "disc_r5mm", "ellipse_5x3mm"}
    for trial in ds:
        ev = events_of(trial)
        assert np.all(np.diff(ev.t) >= 0)
        assert set(np.unique(ev.polarity)) == {-1, 1}
        assert ev.x.between(0, 189).all()
        assert ev.y.between(0, 179).all()
        assert 1_000 < len(ev) < 50_000
        assert np.isfinite(trial.labels["slip_onset_s"])


def test_same_seed_same_tables_and_different_seed_differs():
    """The same seed reproduces every table exactly; another seed gives other events."""
    scene = compose_scene()
    a, b, c = (
        scene.simulate(2, seed=4),
        scene.simulate(2, seed=4),
        scene.simulate(2, seed=5),
    )
    pd.testing.assert_frame_equal(a.stream("events"), b.stream("events"))
    pd.testing.assert_frame_equal(a.stream("truth_contact"), b.stream("truth_contact"))
    assert len(a.stream("events")) != len(c.stream("events")) or not a.stream(
        "events"
    ).equals(c.stream("events"))


def test_cli_simulate_writes_a_loadable_dataset(tmp_path):
    """`slipkit simulate scene=davis_release` writes an event dataset that loads back."""
    out = tmp_path / "davis"
    cli_main(
        [
            "simulate",
            f"scene={SCENE}",
            "n_trials=2",
            "seed=1",
            f"out={out}",
            "progress=false",
            "summary=false",
        ]
    )
    ds = load_dataset(out)
    assert ("davis", 2) == (ds.sensor, len(ds))
    assert ds.streams["events"].rate_hz is None
    assert len(ds.stream("events")) > 0


def test_onset_label_follows_the_truth_area_curve():
    """The onset is the first truth frame in the release with less area than the hold minimum."""
    scene = compose_scene()
    for i in range(3):
        trial = scene.run_trial(i, seed=1)
        patch = phases(scene, i, 1)
        truth = trial.streams["truth_contact"]
        on = trial.labels["slip_onset_s"]
        hold = truth[
            (truth.t >= patch.press_start + patch.press_s)
            & (truth.t < patch.release_start)
        ]
        at = truth[truth.t >= on - 1e-9].iloc[0]
        assert at.area_px < hold.area_px.min() <= truth[truth.t < on].iloc[-1].area_px
        assert patch.release_start <= on < patch.release_start + patch.release_s


# -- effect signatures -----------------------------------------------------------------------


def test_positive_area_exceeds_negative_during_release_not_during_press():
    """Per 10 ms window, positive-event area beats negative area in the release and not in the press."""
    scene = compose_scene()
    rel_frac, press_frac = [], []
    for i in range(4):
        trial = scene.run_trial(i, seed=2)
        patch = phases(scene, i, 2)
        ev = events_of(trial)
        pos, neg = window_areas(
            ev, patch.release_start, patch.release_start + patch.release_s
        )
        rel_frac.append(np.mean(pos > neg))
        pos, neg = window_areas(
            ev, patch.press_start, patch.press_start + patch.press_s
        )
        press_frac.append(np.mean(pos > neg))
    assert min(rel_frac) >= 0.8, rel_frac
    assert max(press_frac) <= 0.2, press_frac


def test_contact_events_fire_once_per_crossing_with_the_papers_polarity():
    """contact_events alone: each covered pixel fires -1 in the press and +1 in the release."""
    scene = scene_with(CONTACT)
    trial = scene.run_trial(0, seed=3)
    patch = phases(scene, 0, 3)
    ev = events_of(trial)
    hold_area = trial.streams["truth_contact"].area_px.max()
    neg, pos = ev[ev.polarity < 0], ev[ev.polarity > 0]
    assert (hold_area, hold_area) == (len(neg), len(pos))
    assert neg.t.between(
        patch.press_start, patch.press_start + patch.press_s + 1e-3
    ).all()
    assert pos.t.between(
        patch.release_start, patch.release_start + patch.release_s + 1e-3
    ).all()
    assert len(neg) == len(neg[["x", "y"]].drop_duplicates())
    tripled = events_of(
        scene_with({"contact_events": {"events_per_pixel": 3}}).run_trial(0, seed=3)
    )
    assert 3 * len(ev) == len(tripled)


def test_without_contact_events_no_polarity_follows_the_phases():
    """Removing contact_events leaves no contact-driven events: release windows are balanced noise."""
    scene = scene_with(BACKGROUND)
    trial = scene.run_trial(0, seed=4)
    patch = phases(scene, 0, 4)
    ev = events_of(trial)
    rel = ev[
        (ev.t >= patch.release_start) & (ev.t < patch.release_start + patch.release_s)
    ]
    n_pos, n_neg = int((rel.polarity > 0).sum()), int((rel.polarity < 0).sum())
    assert abs(n_pos - n_neg) < 4 * math.sqrt(n_pos + n_neg)


def test_vibration_incidents_are_short_balanced_bursts_without_area_loss():
    """vibration_incidents alone: bursts of both polarities, equal counts, before the release, truth unchanged."""
    scene = scene_with(VIBRATION)
    for i in range(3):
        trial = scene.run_trial(i, seed=5)
        patch = phases(scene, i, 5)
        ev = events_of(trial)
        assert len(ev) > 0
        assert int((ev.polarity > 0).sum()) == int((ev.polarity < 0).sum())
        assert ev.t.between(patch.press_start, patch.release_start).all()
        bare = scene_with().run_trial(i, seed=5)
        pd.testing.assert_frame_equal(
            bare.streams["truth_contact"], trial.streams["truth_contact"]
        )
        assert 0 == len(events_of(bare))


def test_each_vibration_incident_restores_every_pixel_it_touched():
    """Within one incident each pixel's events alternate in polarity and end where they started."""
    scene = scene_with(
        {"vibration_incidents": {"rate_hz": 1.0, "rise_s": 0.003, "fall_s": 0.015}}
    )
    for i in range(6):
        ev = events_of(scene.run_trial(i, seed=6))
        net = ev.groupby(["x", "y"]).polarity.sum()
        assert (net == 0).all()


def test_background_events_appear_only_when_listed():
    """background_events fills the no-contact phases at the set rate; without it they stay empty."""
    noisy = scene_with(CONTACT, BACKGROUND)
    quiet = scene_with(CONTACT)
    for i in range(2):
        patch = phases(noisy, i, 7)
        ev, ev0 = (
            events_of(noisy.run_trial(i, seed=7)),
            events_of(quiet.run_trial(i, seed=7)),
        )
        pre = ev[ev.t < patch.press_start]
        expected = 2000.0 * patch.press_start
        assert abs(len(pre) - expected) < 5 * math.sqrt(expected)
        assert 0 == int((ev0.t < patch.press_start).sum())
        assert 0 == int((ev0.t > patch.release_start + patch.release_s + 1e-3).sum())


# -- validation ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"width_px": 0}, "width_px"),
        ({"pixel_mm": -1.0}, "pixel_mm"),
        ({"press_s": [0.5, 0.2]}, "press_s"),
        ({"objects": {"huge": [30.0, 30.0]}}, "objects"),
        ({"objects": {"bad": [1.0]}}, "objects.bad"),
    ],
)
def test_bad_config_raises_naming_the_key(kwargs, key):
    """An out-of-range config value raises a SimulationError naming its key."""
    with pytest.raises(SimulationError, match=f"model.{key}"):
        DavisRelease(**kwargs)


def test_bad_effect_parameters_raise():
    """Effect parameters out of range raise a SimulationError naming the effect."""
    for effects in (
        {"contact_events": {"events_per_pixel": 0}},
        {"vibration_incidents": {"shift_px": [3.0, 1.0]}},
        {"background_events": {"rate_hz": -1.0}},
    ):
        with pytest.raises(SimulationError, match=next(iter(effects))):
            scene_with(effects).run_trial(0, seed=0)
