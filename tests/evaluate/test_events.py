"""Trial events (slipkit.evaluate.events): hand-computed alarms, outcomes, costs and operating points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slipkit.errors import SlipkitError
from slipkit.evaluate.events import (
    Cost,
    Limits,
    TrialTruth,
    alarm_indices,
    choose_operating_point,
    parse_cost,
    parse_limits,
    slipped_of,
    summarise,
    threshold_grid,
    trial_cost,
    trial_events,
)

T = np.arange(20) / 100.0  # 20 samples at 100 Hz: 10 ms apart


def _scores(*fired: int) -> np.ndarray:
    s = np.zeros(20)
    s[list(fired)] = 1.0
    return s


def test_an_alarm_is_the_kth_sample_of_a_run_and_once_per_run() -> None:
    """Runs 2-4 and 7-8 with k=2 alarm at 3 and 8; k=3 only at 4; a NaN breaks a run."""
    s = _scores(2, 3, 4, 7, 8)
    assert [3, 8] == alarm_indices(s, 0.5, 2).tolist()
    assert [4] == alarm_indices(s, 0.5, 3).tolist()
    assert [2, 7] == alarm_indices(s, 0.5, 1).tolist()
    s[3] = math.nan
    assert [8] == alarm_indices(s, 0.5, 2).tolist()


def test_a_detection_after_the_onset_gives_its_delay_and_cost() -> None:
    """Onset 100 ms, alarm at sample 13 (k=2: run 12-13): detected 30 ms late, cost 0.06."""
    truth = TrialTruth("a", T, True, 0.10)
    ev = trial_events(truth, _scores(12, 13, 14), 0.5, 2)
    assert (True, False, 30.0) == (
        ev.detected,
        ev.early_alarm,
        pytest.approx(ev.delay_ms),
    )
    assert 0.06 == pytest.approx(trial_cost(ev, Cost()))


def test_an_early_alarm_whose_run_spans_the_onset_is_early_and_missed() -> None:
    """A run from 80 ms on declares one alarm, before the onset: early, no detection, cost 1.2."""
    truth = TrialTruth("a", T, True, 0.10)
    ev = trial_events(truth, _scores(*range(8, 20)), 0.5, 1)
    assert (False, True, 1, 1) == (
        ev.detected,
        ev.early_alarm,
        ev.n_alarms,
        ev.false_alarms,
    )
    assert 1.2 == pytest.approx(trial_cost(ev, Cost()))


def test_a_late_detection_costs_no_more_than_a_miss() -> None:
    """Delay 90 ms at 0.02 per ms would be 1.8: capped at the miss cost 1.0."""
    truth = TrialTruth("a", T, True, 0.10)
    ev = trial_events(truth, _scores(19), 0.5, 1)
    assert 1.0 == pytest.approx(trial_cost(ev, Cost(delay_ms=0.02)))


def test_unknown_onset_is_scored_on_detection_only() -> None:
    """slipped, onset unknown: detected by any alarm, no early alarm, delay or false alarms."""
    truth = TrialTruth("a", T, True, math.nan)
    ev = trial_events(truth, _scores(3), 0.5, 1)
    assert (True, None, 0, 0.0) == (
        ev.detected,
        ev.early_alarm,
        ev.false_alarms,
        ev.nonslip_s,
    )
    assert math.isnan(ev.delay_ms)
    assert 0.0 == trial_cost(ev, Cost())
    summary = summarise([ev], Cost())
    assert (1.0, 1, 1) == (
        summary["detected_rate"],
        summary["unknown_onset_trials"],
        summary["event_trials"],
    )
    assert math.isnan(summary["early_alarm_rate"])


def test_trial_balanced_accuracy_reads_trial_labels_only() -> None:
    """Slip or wiggle, no onsets: 2 of 3 slips fire, 1 of 4 wiggles fires ->
    (2/3 + 3/4) / 2; one kind of trial alone has none."""
    slips = [
        trial_events(TrialTruth(f"s{i}", T, True, math.nan), _scores(*a), 0.5, 1)
        for i, a in enumerate([(3,), (8,), ()])
    ]
    wiggles = [
        trial_events(TrialTruth(f"w{i}", T, False), _scores(*a), 0.5, 1)
        for i, a in enumerate([(5,), (), (), ()])
    ]
    summary = summarise([*slips, *wiggles], Cost())
    assert summary["trial_balanced_accuracy"] == pytest.approx((2 / 3 + 3 / 4) / 2)
    assert math.isnan(summarise(slips, Cost())["trial_balanced_accuracy"])
    assert math.isnan(summarise(wiggles, Cost())["trial_balanced_accuracy"])


def test_a_trial_of_unknown_outcome_is_left_out() -> None:
    """slipped None: no outcome, NaN cost, not counted in event_trials."""
    ev = trial_events(TrialTruth("a", T, None, math.nan), _scores(3), 0.5, 1)
    assert (None, None) == (ev.detected, ev.early_alarm)
    assert math.isnan(trial_cost(ev, Cost()))
    assert 0 == summarise([ev], Cost())["event_trials"]


def test_a_no_slip_trial_with_an_alarm_is_an_early_alarm_and_a_false_alarm() -> None:
    """A touch without slip: any alarm is early (cost 0.2) and false, over 0.2 s of non-slip time."""
    ev = trial_events(TrialTruth("t", T, False), _scores(5, 15), 0.5, 1)
    assert (None, True, 2) == (ev.detected, ev.early_alarm, ev.false_alarms)
    assert 0.2 == pytest.approx(ev.nonslip_s)
    assert 0.2 == pytest.approx(trial_cost(ev, Cost()))
    assert 600.0 == pytest.approx(summarise([ev], Cost())["false_alarms_per_min"])


def test_disturbances_fire_with_an_alarm_inside_plus_the_tolerance() -> None:
    """Two knocks, 20-40 ms and 100-120 ms; an alarm at 130 ms fires the second only with 10 ms tolerance."""
    truth = TrialTruth("a", T, False, disturbances=((0.02, 0.04), (0.10, 0.12)))
    assert 0 == trial_events(truth, _scores(13), 0.5, 1).disturbances_fired
    ev = trial_events(truth, _scores(13), 0.5, 1, tolerance_s=0.0101)
    assert (2, 1) == (ev.disturbances, ev.disturbances_fired)
    assert 0.5 == summarise([ev], Cost())["alarms_per_disturbance"]


def test_per_sample_truth_sets_the_non_slip_time() -> None:
    """With a slip truth of samples 10-14 only, an alarm at 17 (after the slip) is a false alarm."""
    slip = np.zeros(20, dtype=bool)
    slip[10:15] = True
    truth = TrialTruth("a", T, True, 0.10, slip=slip)
    ev = trial_events(truth, _scores(11, 17), 0.5, 1)
    assert (True, 1, 15) == (ev.detected, ev.false_alarms, round(ev.nonslip_s * 100))


def test_summary_rates_over_hand_made_trials() -> None:
    """Detected 1 of 2 slips (delay 20 ms), no early alarm in 3 trials, cost (0.04 + 1 + 0) / 3."""
    events = [
        trial_events(TrialTruth("a", T, True, 0.10), _scores(12), 0.5, 1),
        trial_events(TrialTruth("b", T, True, 0.10), _scores(), 0.5, 1),
        trial_events(TrialTruth("c", T, False), _scores(), 0.5, 1),
    ]
    s = summarise(events, Cost())
    assert (0.5, 0.0, 2, 1, 3) == (
        s["detected_rate"],
        s["early_alarm_rate"],
        s["n_slips"],
        s["missed"],
        s["event_trials"],
    )
    assert 20.0 == pytest.approx(s["delay_ms"])
    assert (1.04 / 3) == pytest.approx(s["cost"])


def test_the_operating_point_is_the_cheaper_one_on_the_validation_trials() -> None:
    """Slip trials score 0.9 from the onset, a touch trial has a 1-sample spike of 0.95: threshold
    above 0.95 misses every slip (cost 1), 0.9 with k=1 alarms on the touch (0.2); k=2 ignores the
    spike and costs only 10 ms of delay, so (0.9, 2) is chosen."""
    slip = np.where(T >= 0.10, 0.9, 0.1)
    touch = np.full(20, 0.1)
    touch[5] = 0.95
    truths = [
        TrialTruth("s1", T, True, 0.10),
        TrialTruth("s2", T, True, 0.10),
        TrialTruth("t1", T, False),
    ]
    point = choose_operating_point(
        truths,
        [slip, slip, touch],
        thresholds=[0.5, 0.9, 0.96],
        debounce_ks=[1, 2, 3],
        limits=Limits(max_early_alarm_rate=None),
    )
    assert (0.9, 2, True) == (point.threshold, point.debounce_k, point.within_limits)
    assert (2 * 0.02 / 3) == pytest.approx(point.summary["cost"])
    assert ["s1", "s2", "t1"] == point.chosen_on


def test_a_limit_passes_over_the_cheaper_point() -> None:
    """With early alarms at 0.05, alarming at 0.5 (on the touch too) is cheaper than waiting
    80 ms for 0.8; an early-alarm limit of 0 % passes it over for the later point."""
    slip = np.full(20, 0.1)
    slip[10:] = 0.6
    slip[18:] = 0.9
    touch = np.full(20, 0.1)
    touch[5:8] = 0.7
    truths = [TrialTruth("s", T, True, 0.10), TrialTruth("t", T, False)]
    kw = {"thresholds": [0.5, 0.8], "debounce_ks": [1], "cost": Cost(early_alarm=0.05)}
    free = choose_operating_point(truths, [slip, touch], limits=Limits(None), **kw)  # type: ignore[arg-type]
    held = choose_operating_point(
        truths,
        [slip, touch],
        limits=Limits(max_early_alarm_rate=0.0),
        **kw,  # type: ignore[arg-type]
    )
    assert (0.5, 0.8) == (free.threshold, held.threshold)
    assert (0.5, 0.0) == (
        free.summary["early_alarm_rate"],
        held.summary["early_alarm_rate"],
    )


def test_a_point_no_better_than_no_detector_is_no_operating_point() -> None:
    """Silent (cost 0.5, every slip missed) is within a 0 % early-alarm limit but costs what no
    detector costs: the cheaper point over the limit is kept, flagged."""
    slip = np.where(T >= 0.10, 0.9, 0.1)
    touch = np.full(20, 0.1)
    touch[5:8] = 0.95
    point = choose_operating_point(
        [TrialTruth("s", T, True, 0.10), TrialTruth("t", T, False)],
        [slip, touch],
        thresholds=[0.5, 0.96],
        debounce_ks=[1],
        limits=Limits(max_early_alarm_rate=0.0),
    )
    assert (0.5, False, 0.5) == (
        point.threshold,
        point.within_limits,
        point.summary["cost_without_detector"],
    )


def test_no_point_within_the_limits_keeps_the_cheapest_flagged() -> None:
    """Every point alarms on the touch: the cheapest is kept, within_limits False with the reason."""
    s = np.full(20, 0.9)
    point = choose_operating_point(
        [TrialTruth("t", T, False)],
        [s],
        thresholds=[0.5],
        debounce_ks=[1],
        limits=Limits(max_early_alarm_rate=0.25),
    )
    assert (
        False,
        "no candidate within the limits that beats no detector; the cheapest one "
        "(early alarms 100 % > 25 %)",
    ) == (
        point.within_limits,
        point.note,
    )


def test_threshold_grid_holds_the_extra_point_and_the_top_tail() -> None:
    """The grid holds the ROC choice given as extra and reaches the top score."""
    scores = [np.arange(1000.0)]
    grid = threshold_grid(scores, 16, extra=[123.45])
    assert 123.45 in grid
    assert 999.0 == grid.max()
    assert (grid > 990).sum() >= 3


def test_slipped_label_is_separate_from_the_onset() -> None:
    """slipped 1 with an unknown onset is a slip; NaN slipped with NaN onset unknown; no label: onset."""
    assert True is slipped_of({"slipped": 1.0}, math.nan)
    assert False is slipped_of({"slipped": 0.0}, math.nan)
    assert None is slipped_of({"slipped": math.nan}, math.nan)
    assert True is slipped_of({"slipped": math.nan}, 0.4)
    assert False is slipped_of({}, math.nan)


@pytest.mark.parametrize(
    ("node", "match"),
    [
        ({"miss": -1}, r"cost\.miss: must be a number >= 0"),
        ({"mis": 1.0}, r"cost\.mis: unknown cost"),
        (1.0, "must be a mapping"),
    ],
)
def test_bad_costs_are_named(node: object, match: str) -> None:
    """A negative weight, an unknown key or no mapping: one SlipkitError naming the key."""
    with pytest.raises(SlipkitError, match=match):
        parse_cost(node, "comparison.verdict.cost")  # type: ignore[arg-type]


def test_bad_limits_are_named() -> None:
    """A limit above 1 names its key."""
    with pytest.raises(SlipkitError, match=r"verdict\.max_early_alarm_rate"):
        parse_limits({"max_early_alarm_rate": 25}, "verdict")


def test_a_bad_operating_point_is_named() -> None:
    """A debounce of 0 or an unknown key in task.operating_point: one line naming it."""
    from slipkit.evaluate.events import parse_operating_point

    with pytest.raises(SlipkitError, match=r"task\.operating_point\.debounce: must be"):
        parse_operating_point({"debounce": [0]})
    with pytest.raises(SlipkitError, match=r"task\.operating_point\.thresold: unknown"):
        parse_operating_point({"thresold": 8})
