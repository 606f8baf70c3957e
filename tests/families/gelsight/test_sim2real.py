"""Sim-to-real: settings and thresholds chosen on simulated trials alone, scored on the
other set's every trial, beside that set's own nested CV."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("cv2")

import slipkit.families.gelsight.effects  # noqa: F401  (registers the effects)
from slipkit.data.io import save_dataset
from slipkit.errors import SlipkitError
from slipkit.families.gelsight.report import load_trials
from slipkit.families.gelsight.report import run as report_run
from slipkit.families.gelsight.scene import GelSightGrasp
from slipkit.families.gelsight.sim2real import Loaded, main, run, sim_to_real
from slipkit.sim.core import Scene


def simulated(seed: int, n: int = 30, **kw: object):  # type: ignore[no-untyped-def]
    model = GelSightGrasp(
        duration_s=4.0,
        onset_s=[1.0, 2.5],
        set_down_s=3.0,
        objects=6,
        **kw,  # type: ignore[arg-type]
    )
    fx = {"shake": {"count": [1, 2], "amplitude": [0.02, 0.1]}, "gel_shear": {}}
    return Scene("g", model, fx).simulate(n, seed)


@pytest.mark.slow
def test_a_detector_chosen_on_simulation_separates_another_simulated_set() -> None:
    sim, other = simulated(0), simulated(1)
    res = sim_to_real(
        "divergence_contact", load_trials(sim), load_trials(other), seed=0
    )
    assert res["balanced_accuracy"] > 0.8
    majority = sim_to_real("majority", load_trials(sim), load_trials(other), seed=0)
    assert majority["balanced_accuracy"] == 0.5


def test_the_command_can_leave_the_real_column_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = save_dataset(simulated(0, 12), tmp_path / "sim")
    out = tmp_path / "res.json"
    args = ["--real", str(data), "--sim", str(data), "--seeds", "0", "--only"]
    main([*args, "majority", "--skip-real", "--out", str(out)])
    res = json.loads(out.read_text().replace("NaN", "null"))
    assert res["results"]["majority"]["real"]["balanced_accuracy"]["mean"] is None
    sim = res["results"]["majority"]["sim"]
    assert sim["balanced_accuracy_full_length"] == {"mean": 0.5, "sd": 0.0}
    header, _, row = capsys.readouterr().out.splitlines()[:3]
    assert header.count("full-length clips") == 2
    assert row.endswith("| n/a | n/a |")


def clips(lengths: list[int], y: list[int]) -> Loaded:
    """Trials of two fingertips that are only ``lengths`` frames long: what a control
    of clip length reads."""
    trials = [
        {"camera_0": np.zeros((n, 4)), "camera_2": np.zeros((n, 4))} for n in lengths
    ]
    groups = np.array([f"o{i % 4}" for i in range(len(y))])
    return trials, np.array(y), groups, [str(i) for i in range(len(y))]


def test_the_full_length_column_scores_only_the_full_length_real_trials() -> None:
    # simulated clips all 100 frames; real ones 150 frames, but half the slips stopped
    # early (60): clip length marks those slips, and nothing on the full-length trials
    sim = clips([100] * 8, [0, 1] * 4)
    real = clips([150, 60, 150, 150, 150, 60, 150, 150], [0, 1] * 4)
    res = sim_to_real("clip_length", sim, real, seed=0)
    assert res["balanced_accuracy"] == 0.75
    assert res["balanced_accuracy_full_length"] == 0.5
    # without both classes among the full-length trials there is no such score
    only_wiggles = clips([150, 60, 150, 60], [0, 1, 0, 1])
    res = sim_to_real("clip_length", sim, only_wiggles, seed=0)
    assert res["balanced_accuracy"] == 1.0
    assert np.isnan(res["balanced_accuracy_full_length"])


def test_run_reports_both_sides_over_seeds() -> None:
    sims = [simulated(0, 30), simulated(1, 30)]
    real = simulated(2, 30)
    res = run(real, sims, [0, 1], ["majority", "clip_length"])
    row = res["results"]["majority"]
    assert row["sim"]["balanced_accuracy"] == {"mean": 0.5, "sd": 0.0}
    assert np.isfinite(row["real"]["balanced_accuracy"]["mean"])
    assert len(row["per_seed"]["sim"]) == 2
    # the trained-on-real column read from the report's JSON is the one computed
    reported = json.loads(json.dumps(report_run(real, [0, 1], ["clip_length"])))
    again = run(real, sims, [0, 1], ["clip_length"], real_report=reported)
    assert (
        again["results"]["clip_length"]["real"] == res["results"]["clip_length"]["real"]
    )
    # the full-length column on both sides; trained on real, the report's own
    clip = again["results"]["clip_length"]
    full = "balanced_accuracy_full_length"
    assert clip["real"][full] == reported["results"]["clip_length"][full]
    # equal-length clips: every trial is full length
    assert clip["sim"][full] == clip["sim"]["balanced_accuracy"]
    del reported["results"]["clip_length"]["per_seed"][0][full]
    with pytest.raises(SlipkitError, match=full):
        run(real, sims, [0, 1], ["clip_length"], real_report=reported)
    skipped = run(real, sims[:1], [0], ["majority"], skip_real=True)
    assert np.isnan(skipped["results"]["majority"]["real"]["balanced_accuracy"]["mean"])
    with pytest.raises(SlipkitError, match="seed 2"):
        run(real, sims[:1], [2], ["clip_length"], real_report=reported)


def test_a_simulated_set_needs_the_fingertip_streams_the_report_reads() -> None:
    from types import SimpleNamespace
    from typing import Any, cast

    from slipkit.families.gelsight.sim2real import _check_streams

    def ds(*names: str) -> Any:
        return cast(Any, SimpleNamespace(streams=dict.fromkeys(names)))

    real = ds("camera_0", "camera_2", "fingertips")
    _check_streams(
        real, ds("camera_0", "camera_2"), "sim"
    )  # the side-by-side stream is not read
    with pytest.raises(
        SlipkitError, match=r"lacks the real set's streams \['camera_2'\]"
    ):
        _check_streams(real, ds("camera_0", "fingertips"), "sim")
