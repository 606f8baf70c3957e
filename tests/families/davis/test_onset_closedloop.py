"""The DAVIS onset rule on the closed loop's own event frames (5 ms, with vibration and noise)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from slipkit import config_dir
from slipkit.closedloop.commands import load_scenario, scenario_of
from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.plant import PlantState
from slipkit.families.davis.onset import DavisOnset
from slipkit.families.davis.scenario import frame_channels
from slipkit.sim.commands import build_scene


class _Onset(Detector):
    """Scores the 5 ms frames a bundle would read with DavisOnset; never declares."""

    name = "onset"

    def __init__(self) -> None:
        self.channels = frame_channels(180, 190)
        self.rate_hz = 200.0
        self.det = DavisOnset().fit(np.empty((0, 4)))
        self.seen: list[tuple[float, float, bool, float]] = []

    def decide(self, state: PlantState, frame: Callable[[], np.ndarray]) -> bool:
        f = np.asarray(frame()).reshape(1, 2, 180, 190)
        slip = bool(self.det.score(self.det.features(f))[0] > 0)
        self.seen.append((state.t, state.onset_s, slip, state.drop_mm))
        return False


def _run(condition: float, seed: int) -> list[tuple[float, float, bool, float]]:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="closedloop", overrides=["closedloop=davis"])
        scen = load_scenario(cfg)
        scene = build_scene(compose("train", [f"scene={scen.scene}"]).scene)
    plant: Any = OmegaConf.to_container(scen.plant, resolve=True)
    det = _Onset()
    scenario_of(scen).run_trial(
        scene, det, plant, seed=seed, condition_index=0, trial=0, condition=condition
    )
    return det.seen


@pytest.mark.slow
def test_two_slip_frames_in_a_row_come_after_the_onset_before_the_slide() -> None:
    """Fast and slow lifts (no response): the first two consecutive slip frames end after
    the incipient-slip onset and before the object has slid 0.5 mm."""
    out = []
    for condition in (0.03, 0.3):
        seen = _run(condition, seed=1)
        onset = next(o for _, o, _, _ in seen if not math.isnan(o))
        slid = next(t for t, _, _, d in seen if d > 0.5)
        pairs = [b[0] for a, b in itertools.pairwise(seen) if a[2] and b[2]]
        first = min(pairs) if pairs else math.inf
        out.append((onset < first, first <= slid))
    assert [(True, True), (True, True)] == out
