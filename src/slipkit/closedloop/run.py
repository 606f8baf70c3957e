"""Run closed-loop trials: plant, sensor, detector and the paper's controller in one loop.

Per frame (``1 / rate_hz``): the sensor frame is built from the plant's current state,
the detector decides, on a declared slip the controller issues its response (the
actuator delivers it after its latency and lag), then the plant advances one frame.
What the plant, the sensor and the controller are is the family's scenario
(:mod:`slipkit.closedloop.scenarios`); this module holds the outcome record and the
driver over seeds, conditions and trials.

Every trial of one seed uses the same draws for every detector (trial ``i`` of
condition ``j`` of seed ``s`` draws from ``default_rng([s, j, i])``), so detectors are
compared on identical objects and noise up to their first declaration.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from slipkit.closedloop.detectors import Detector
from slipkit.closedloop.scenarios import ClosedLoopScenario
from slipkit.sim.core import Scene


@dataclass(frozen=True)
class Outcome:
    """One closed-loop trial.

    Attributes
    ----------
    detector : str
        Detector name.
    seed, condition_index, trial : int
        Which draw.
    condition : float
        The trial's condition (the scenario's ``condition_label``: TacTip the arm's
        retraction speed, mm/s).
    mass_kg : float
        Object mass, kg.
    object : str
        Stimulus.
    onset_s : float
        Plant slip onset, s (NaN: never slipped).
    declared_s : float
        First declared slip, s (NaN: never).
    false_alarm : bool
        Declared before the plant slipped.
    delay_ms : float
        Declared minus onset, ms (NaN unless declared at or after the onset).
    arrest_s : float
        When the slip stopped, s (NaN: not arrested).
    slip_mm : float
        Distance slid by the end (the plant's travel when dropped), mm.
    dropped : bool
        The object was lost (slid past the travel or still sliding at the end).
    onset_to_arrest_ms : float
        Arrest minus onset, ms (NaN unless arrested).
    extra_force_N, extra_impulse_Ns : float
        Grip force a false alarm added above what the trial would have had without
        it (TacTip: above the open-loop retraction's, up to the time the retraction
        would have let the object slip): peak (N) and integral (N s); 0 without a
        false alarm.
    frames : int
        Frames the detector saw.
    """

    detector: str
    seed: int
    condition_index: int
    trial: int
    condition: float
    mass_kg: float
    object: str
    onset_s: float
    declared_s: float
    false_alarm: bool
    delay_ms: float
    arrest_s: float
    slip_mm: float
    dropped: bool
    onset_to_arrest_ms: float
    extra_force_N: float
    extra_impulse_Ns: float
    frames: int

    def row(self) -> dict[str, Any]:
        """The outcome as a flat dict (one CSV row)."""
        return asdict(self)


def speed_grid(lo: float, hi: float, n: int) -> list[float]:
    """``n`` log-spaced speeds from ``lo`` to ``hi`` (mm/s), rounded to 3 significant digits."""
    return [float(f"{v:.3g}") for v in np.geomspace(lo, hi, int(n))]


def run_detector(
    scenario: ClosedLoopScenario,
    scene: Scene,
    detector: Detector,
    plant_cfg: Mapping[str, Any],
    *,
    seeds: Sequence[int],
    conditions: Sequence[float],
    trials_per_condition: int,
) -> list[Outcome]:
    """Every (seed, condition, trial) of ``scenario`` with ``detector`` in the loop."""
    out: list[Outcome] = []
    for seed in seeds:
        for j, condition in enumerate(conditions):
            for i in range(int(trials_per_condition)):
                out.append(
                    scenario.run_trial(
                        scene,
                        detector,
                        plant_cfg,
                        seed=int(seed),
                        condition_index=j,
                        trial=i,
                        condition=float(condition),
                    )
                )
    return out
