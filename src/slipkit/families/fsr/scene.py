"""FSR scene: a probe pressed on a force-sensing resistor, then slid across it.

Follows the first experimental session of Gentile et al. 2020 (Mechatronics 70): a
robot arm presses a probe on an FSR 402 with a constant normal force, holds, then passes
over the whole sensor surface in a set time (Table 1: 1.2-4.7 N, 1-5 s); the conditioned
voltage is sampled at 2 kHz. The backbone is the static contact (the probe pressed from
the first sample, leaving the sensor at the end of the pass) seen through the inverse of
the calibration eq. 6; the touch (press), the slip vibrations and the impulsive
disturbances are effects (:mod:`slipkit.families.fsr.effects`). See ``docs/families/fsr.md``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import LabelSpec, StreamSpec
from slipkit.families.fsr.physics import (
    DEFAULT_CALIBRATION,
    OUTPUT_RANGE_V,
    max_force,
    voltage_from_force,
)
from slipkit.sim import params
from slipkit.sim.core import SceneState, SimulationError, phase_times, sample_times

Range = tuple[float, float]


def _range(value: Any, key: str, strict: bool = True) -> Range:
    """A positive config number or ``[low, high]`` range (``strict=False``: >= 0)."""
    return params.value_range(key, value, lo=0.0, strict_lo=strict)


def _scalar(value: Any, key: str, strict: bool = True) -> float:
    return params.single(key, value, lo=0.0, strict_lo=strict)


def _draw(rng: np.random.Generator, r: Range) -> float:
    return float(params.draw(rng, r))


class FSRProbeSlide:
    """A probe pressed on an FSR, held, slid across it and off (Gentile et al. 2020).

    Phases: ``approach`` (``approach_s``; the ``fsr_touch`` effect presses the probe at
    its end, without it the probe is pressed from the first sample), ``hold``
    (``hold_s``, pressed at ``normal_force_N``), ``slide`` (``pass_s``, the probe passes
    over the sensor: slip onset), ``release`` (``release_s``, the probe leaves the
    sensor and the force falls to zero, raised-cosine), ``tail`` (``tail_s``).

    Parameters
    ----------
    rate_hz : float
        Sample rate of the conditioned voltage (Hz); the paper: 2 kHz.
    approach_s, hold_s, release_s, tail_s : float
        Phase durations (s).
    pass_s : float or [low, high]
        Duration of the pass over the sensor (s), drawn per trial; Table 1: 1, 3, 5 s.
    normal_force_N : float or [low, high]
        Probe normal force (N), drawn per trial; Table 1: 1.2, 3.6, 4.7 N.
    calibration : list of 5 floats
        ``p1..p5`` of eq. 6, F (N) from V (V); default: see :mod:`slipkit.families.fsr.physics`.
    output_range_V : [low, high]
        The conditioned output's range (V).
    """

    sensor = "fsr"
    groups: tuple[str, ...] = ()

    def __init__(
        self,
        *,
        rate_hz: float = 2000.0,
        approach_s: float = 0.3,
        hold_s: float = 0.6,
        pass_s: Any = (1.0, 5.0),
        release_s: float = 0.05,
        tail_s: float = 0.2,
        normal_force_N: Any = (1.2, 4.7),
        calibration: Any = DEFAULT_CALIBRATION,
        output_range_V: Any = OUTPUT_RANGE_V,
    ) -> None:
        self.rate_hz = _scalar(rate_hz, "model.rate_hz")
        self.approach_s = _scalar(approach_s, "model.approach_s", strict=False)
        self.hold_s = _scalar(hold_s, "model.hold_s", strict=False)
        self.pass_s = _range(pass_s, "model.pass_s")
        self.release_s = _scalar(release_s, "model.release_s")
        self.tail_s = _scalar(tail_s, "model.tail_s", strict=False)
        self.normal_force_N = _range(normal_force_N, "model.normal_force_N")
        if (
            isinstance(calibration, str)
            or not isinstance(calibration, Sequence)
            or len(calibration) != 5
        ):
            raise SimulationError(
                f"model.calibration must list 5 coefficients p1..p5; got {calibration!r}"
            )
        try:
            self.calibration = tuple(float(c) for c in calibration)
        except (TypeError, ValueError):
            raise SimulationError(
                f"model.calibration must hold numbers; got {calibration!r}"
            ) from None
        try:
            lo, hi = (float(v) for v in output_range_V)
        except (TypeError, ValueError):
            raise SimulationError(
                f"model.output_range_V must be [low, high] in V; got {output_range_V!r}"
            ) from None
        if not hi > lo:
            raise SimulationError(
                f"model.output_range_V must be [low, high] with high > low; got {[lo, hi]}"
            )
        self.output_range_V = (lo, hi)
        try:
            top = max_force(self.calibration, self.output_range_V)
        except ValueError as exc:
            raise SimulationError(f"model.calibration: {exc}") from None
        if self.normal_force_N[1] > top:
            raise SimulationError(
                f"model.normal_force_N up to {self.normal_force_N[1]} N exceeds the "
                f"{top:.3g} N that model.calibration maps inside model.output_range_V"
            )

    def streams(self) -> dict[str, StreamSpec]:
        """``fsr`` (conditioned voltage) and ``truth`` (force, slip events, phases)."""
        return {
            "fsr": StreamSpec(
                "fsr",
                ("voltage",),
                {"voltage": "V"},
                rate_hz=self.rate_hz,
                description="conditioned FSR voltage (falls as the force rises)",
            ),
            "truth_contact": StreamSpec(
                "truth_contact",
                ("force", "slip_event", "sliding", "disturbance"),
                {"force": "N", "slip_event": "1", "sliding": "1", "disturbance": "1"},
                rate_hz=self.rate_hz,
                description="ground truth: normal force on the FSR, slip-event, "
                "sliding and disturbance indicators",
            ),
        }

    def labels(self) -> dict[str, LabelSpec]:
        """Slip onset (start of the pass), normal force, pass duration, slip-event count."""
        return {
            "slip_onset_s": LabelSpec("slip_onset_s", unit="s"),
            "normal_force_N": LabelSpec(
                "normal_force_N", unit="N", description="probe force"
            ),
            "pass_s": LabelSpec("pass_s", unit="s", description="duration of the pass"),
            "n_slip_events": LabelSpec(
                "n_slip_events", unit="1", description="stick-slip events in the pass"
            ),
        }

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """Normal force (N) and pass duration (s) of one trial."""
        return {
            "normal_force_N": _draw(rng, self.normal_force_N),
            "pass_s": _draw(rng, self.pass_s),
        }

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        """The pressed probe's static force through the inverse calibration."""
        del rng
        fn = float(params["normal_force_N"])
        phases = phase_times(
            {
                "approach": self.approach_s,
                "hold": self.hold_s,
                "slide": float(params["pass_s"]),
                "release": self.release_s,
                "tail": self.tail_s,
            }
        )
        duration = phases["tail"][1]
        t = sample_times(duration, self.rate_hz)
        r0, r1 = phases["release"]
        leave = np.clip((t - r0) / (r1 - r0), 0.0, 1.0)
        force = fn * 0.5 * (1.0 + np.cos(np.pi * leave))
        s0, s1 = phases["slide"]
        sliding = ((t >= s0) & (t < s1)).astype(np.float64)
        volts = voltage_from_force(force, self.calibration, self.output_range_V)
        return SceneState(
            time={"fsr": t, "truth_contact": t},
            signals={
                "fsr": volts,
                "force": force,
                "sliding": sliding,
                "slip_event": np.zeros_like(t),
                "disturbance": np.zeros_like(t),
            },
            truth={
                **params,
                "phases": phases,
                "touch_s": phases["approach"][1],
                "slip_onset_s": s0,
                "n_slip_events": 0,
                "calibration": self.calibration,
                "output_range_V": self.output_range_V,
            },
        )

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        """Voltage and ground-truth tables, and the trial's labels."""
        s = state.signals
        streams = {
            "fsr": pd.DataFrame({"t": state.time["fsr"], "voltage": s["fsr"]}),
            "truth_contact": pd.DataFrame(
                {
                    "t": state.time["truth_contact"],
                    "force": s["force"],
                    "slip_event": s["slip_event"].astype(np.int8),
                    "sliding": s["sliding"].astype(np.int8),
                    "disturbance": s["disturbance"].astype(np.int8),
                }
            ),
        }
        labels = {
            "slip_onset_s": float(state.truth["slip_onset_s"]),
            "normal_force_N": float(state.truth["normal_force_N"]),
            "pass_s": float(state.truth["pass_s"]),
            "n_slip_events": int(state.truth["n_slip_events"]),
        }
        # Only a scene listing fsr_polarity sets it, so base datasets keep their columns.
        meta = (
            {"polarity": str(state.truth["polarity"])}
            if "polarity" in state.truth
            else {}
        )
        return streams, labels, meta
