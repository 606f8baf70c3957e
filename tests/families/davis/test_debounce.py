"""DavisRelease chooses the debounce on the training trials by the cost within its limits."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from slipkit.data.dataset import Trial
from slipkit.errors import SlipkitError
from slipkit.families.davis.task import DavisRelease


def _trials_and_frames(n: int = 4) -> tuple[list[Trial], pd.DataFrame]:
    """Slip at 0.5 s; one stray slip frame at 0.2 s, then slip frames from 0.52 s."""
    t_end = np.arange(1, 101) * 0.01
    trials, frames = [], []
    for i in range(n):
        slip = ((t_end >= 0.52) | np.isclose(t_end, 0.2)).astype(int)
        trials.append(Trial(f"t{i}", {}, labels={"slip_onset_s": 0.5}))
        frames.append(
            pd.DataFrame({"trial_id": f"t{i}", "t_end_s": t_end, "slip": slip})
        )
    return trials, pd.concat(frames, ignore_index=True)


def test_a_stray_slip_frame_makes_k2_the_choice() -> None:
    """k = 1 alarms early on every trial (over the 25 % limit); k = 2 does not: k = 2."""
    trials, frames = _trials_and_frames()
    task = DavisRelease(operating_point={"debounce": [1, 2, 3]})
    point = task.choose_debounce(trials, frames)  # type: ignore[arg-type]
    assert point is not None
    assert [2, True, 0.0, 1.0] == [
        point.debounce_k,
        point.within_limits,
        point.summary["early_alarm_rate"],
        point.summary["detected_rate"],
    ]
    at_1, _ = task.trial_events(trials, frames, 1)  # type: ignore[arg-type]
    assert 1.0 == at_1["early_alarm_rate"]


def test_without_a_limit_the_cheaper_k1_stays() -> None:
    """No early-alarm limit and a cheap early alarm: k = 1 (earlier alarm) is chosen."""
    trials, frames = _trials_and_frames()
    task = DavisRelease(
        operating_point={
            "debounce": [1, 2],
            "max_early_alarm_rate": None,
            "cost": {"miss": 1.0, "early_alarm": 0.0, "delay_ms": 0.002},
        }
    )
    point = task.choose_debounce(trials, frames)  # type: ignore[arg-type]
    assert point is not None
    assert 1 == point.debounce_k


def test_no_operating_point_keeps_debounce_1_and_bad_grid_is_refused() -> None:
    trials, frames = _trials_and_frames()
    assert DavisRelease().choose_debounce(trials, frames) is None  # type: ignore[arg-type]
    with pytest.raises(SlipkitError, match=r"operating_point\.debounce"):
        DavisRelease(operating_point={"debounce": [0]})
