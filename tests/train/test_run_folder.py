"""Run folders as later commands read them: final path, checksummed files, sample rate, operating point."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import slipkit.cli as cli
from slipkit import config_dir
from slipkit._files import atomic_dir
from slipkit.data import save_dataset
from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.sim.commands import build_scene
from slipkit.train.commands import evaluate_main, train_main
from slipkit.train.runs import read_run, write_config
from slipkit.train.tasks.detection import (
    Recordings,
    StreamDetection,
    operating_point_line,
)


def _compose(name: str, *overrides: str) -> Any:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=list(overrides))


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A small fsr_roc run (the paper's FSR detector) and what `slipkit train` printed."""
    run = tmp_path_factory.mktemp("runs") / "run"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        train_main(
            _compose(
                "train", "experiment=fsr_roc", "dataset.n_trials=4", f"run_dir={run}"
            )
        )
    return run, buf.getvalue()


@pytest.fixture
def run(trained: tuple[Path, str], tmp_path: Path) -> Path:
    """A copy of the trained run that a test may edit."""
    copy = tmp_path / "run"
    shutil.copytree(trained[0], copy)
    return copy


@pytest.fixture(scope="module")
def unseen(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    """Two FSR trials the run never saw."""
    scfg = _compose("simulate", "scene=fsr_probe_slide")
    return build_scene(scfg.scene).simulate(2, seed=11)


def _with_rate(ds: Dataset, stream: str, rate_hz: float) -> Dataset:
    """``ds`` with ``stream``'s rate relabelled (the samples unchanged)."""
    streams = dict(ds.streams)
    streams[stream] = dataclasses.replace(streams[stream], rate_hz=rate_hz)
    return Dataset(
        sensor=ds.sensor,
        streams=streams,
        trials=ds.trials,
        tables=ds.tables,
        labels=ds.labels,
        groups=ds.groups,
        provenance=ds.provenance,
        name=ds.name,
    )


def _evaluate(run: Path, folder: Path) -> Path:
    out: Path = evaluate_main(
        _compose("evaluate", f"run={run}", f"dataset={folder}", "name=unseen")
    )
    return out


# -- run_dir -------------------------------------------------------------------------------


def test_a_run_written_inside_another_commands_output_records_its_final_path(
    tmp_path: Path,
) -> None:
    """A run written in a temporary folder (slipkit compare's) records where it ends up."""
    final = tmp_path / "compare"
    with atomic_dir(final, kind="comparison") as tmp:
        folder = tmp / "runs" / "svm"
        folder.mkdir(parents=True)
        write_config(OmegaConf.create({"run_dir": str(folder)}), folder)
    recorded = OmegaConf.load(final / "runs" / "svm" / "config.yaml")
    assert str(final / "runs" / "svm") == recorded.run_dir


# -- checksums -----------------------------------------------------------------------------


def test_run_json_lists_a_checksum_of_every_file_a_later_command_reads(
    run: Path,
) -> None:
    """run.json's files holds config, metrics, model and the task's tables (not the log)."""
    files = json.loads((run / "run.json").read_text())["files"]
    assert {"config.yaml", "metrics.json", "model.joblib", "test_trials.csv"} <= set(
        files
    )
    assert "train.log" not in files


def _edit_tpr(run: Path) -> None:
    metrics = json.loads((run / "metrics.json").read_text())
    metrics["test"]["samples"]["tpr"] = 1.0
    (run / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")


def test_an_edited_metric_is_refused_by_export(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """metrics.json edited after training: export exits 2 with one line naming it, writes nothing."""
    _edit_tpr(run)
    out = tmp_path / "bundle"
    with pytest.raises(SystemExit) as info:
        cli.main(["export", f"run={run}", f"out={out}"])
    err = capsys.readouterr().err.strip().splitlines()
    assert (2, 1, False) == (info.value.code, len(err), out.exists())
    assert f"{run / 'metrics.json'}: sha256" in err[0]
    assert "does not match run.json field 'files'" in err[0]


@pytest.mark.parametrize("name", ["config.yaml", "metrics.json", "test_trials.csv"])
def test_an_edited_run_file_is_refused_by_evaluate(
    run: Path, tmp_path: Path, unseen: Dataset, name: str
) -> None:
    """Any checksummed file changed after training: evaluate refuses, naming the file."""
    folder = save_dataset(unseen, tmp_path / "ds")
    with (run / name).open("a") as fh:
        fh.write("\n")
    with pytest.raises(SlipkitError) as info:
        _evaluate(run, folder)
    assert str(info.value).startswith(f"{run / name}: sha256 ")
    assert not (run / "evaluations").exists()


def test_a_run_without_file_checksums_is_refused(run: Path) -> None:
    """A run.json without files (an older slipkit) is refused with a re-train hint."""
    info = json.loads((run / "run.json").read_text())
    del info["files"]
    (run / "run.json").write_text(json.dumps(info))
    with pytest.raises(SlipkitError) as err:
        read_run(run)
    assert str(err.value).startswith(f"{run / 'run.json'}: no field 'files'")
    assert str(err.value).endswith("re-train the run")


def test_an_edited_objective_in_run_json_is_refused(run: Path) -> None:
    """run.json's objective value must be the metrics.json value it names."""
    info = json.loads((run / "run.json").read_text())
    info["objective"]["value"] = 1.0 + float(info["objective"]["value"])
    (run / "run.json").write_text(json.dumps(info))
    with pytest.raises(SlipkitError, match=r"field 'objective\.value'"):
        read_run(run)


def test_read_run_hands_back_the_checked_metrics(run: Path) -> None:
    """Run.metrics is metrics.json as training wrote it."""
    assert json.loads((run / "metrics.json").read_text()) == read_run(run).metrics


# -- sample rate -----------------------------------------------------------------------------


def test_evaluate_refuses_a_dataset_at_another_sample_rate(
    run: Path, tmp_path: Path, unseen: Dataset
) -> None:
    """The run's stream relabelled at half its rate: refused, naming stream and both rates."""
    loaded = read_run(run)
    stream, trained_on = str(loaded.config.task.stream), loaded.info["dataset"]["name"]
    rate = float(unseen.streams[stream].rate_hz or 0.0)
    folder = save_dataset(_with_rate(unseen, stream, rate / 2), tmp_path / "half")
    with pytest.raises(SlipkitError) as info:
        _evaluate(run, folder)
    assert str(info.value).endswith(
        f"stream {stream!r} is sampled at {rate / 2:g} Hz, the run was trained on "
        f"{trained_on!r} at {rate:g} Hz"
    )


def test_evaluate_accepts_float_noise_in_the_sample_rate(
    run: Path, tmp_path: Path, unseen: Dataset
) -> None:
    """A rate off by float round-off (1e-9 relative) is the same rate."""
    stream = str(read_run(run).config.task.stream)
    rate = float(unseen.streams[stream].rate_hz or 0.0)
    folder = save_dataset(
        _with_rate(unseen, stream, rate * (1 + 1e-9)), tmp_path / "noisy"
    )
    assert "metrics.json" == _evaluate(run, folder).name


# -- operating point -------------------------------------------------------------------------


def _two_trials(rate: float = 100.0) -> Recordings:
    """Two 20-sample trials, slip from sample 10 on in each."""
    y = np.array(([0] * 10 + [1] * 10) * 2)
    t = np.tile(np.arange(20) / rate, 2)
    return Recordings(
        X=np.zeros((40, 1)),
        y=y,
        t=t,
        segments=np.repeat([0, 1], 20),
        trial_ids=["a", "b"],
        groups=["", ""],
        onset_s=np.array([0.1, 0.1]),
        reference_s=np.array([math.nan, math.nan]),
        disturbance=None,
        rate_hz=rate,
    )


def test_operating_point_counts_slips_early_alarms_false_alarms_and_delay() -> None:
    """Trial a alarms 70 ms before and 30 ms after its onset, b never: 1/2 detected, 1/2
    early, 1 false alarm in 0.2 s of non-slip time, 30 ms, cost (0.2 + 0.06 + 1) / 2."""
    task = StreamDetection(stream="s", negative_window_s=0.01)
    scores = np.zeros(40)
    scores[[3, 13]] = 1.0
    point = task._at_threshold(_two_trials(), scores, 0.5)["operating_point"]
    assert {
        "threshold": 0.5,
        "debounce_k": 1,
        "detected_rate": 0.5,
        "early_alarm_rate": 0.5,
        "false_alarms_per_min": pytest.approx(300.0),
        "delay_ms": pytest.approx(30.0),
        "n_slips": 2,
        "missed": 1,
        "event_trials": 2,
        "unknown_onset_trials": 0,
        "disturbances": 0,
        "cost": pytest.approx(0.63),
        "cost_without_detector": pytest.approx(1.0),
    } == {
        k: v
        for k, v in point.items()
        if k
        not in ("alarms_per_disturbance", "delay_p90_ms", "trial_balanced_accuracy")
    }
    assert math.isnan(point["trial_balanced_accuracy"])  # slips only, no non-slip trial


def test_operating_point_line_reads_as_the_deployed_detector() -> None:
    """36 of 40 slips, 10 % early, 0.8 false alarms per minute, 42 ms (p90 80): one line."""
    test = {
        "threshold": 8.0,
        "operating_point": {
            "threshold": 8.0,
            "debounce_k": 2,
            "n_slips": 40,
            "missed": 4,
            "event_trials": 40,
            "early_alarm_rate": 0.1,
            "false_alarms_per_min": 0.8,
            "delay_ms": 42.2,
            "delay_p90_ms": 80.4,
            "cost": 0.213,
        },
    }
    assert (
        "fsr at threshold 8 V/s, debounce 2: slips detected 36/40 (90 %), early alarms "
        "10 % of trials, false alarms 0.8 /min, delay median 42 ms (p90 80 ms), cost "
        "0.213 over 40 trials"
    ) == operating_point_line("fsr", test, "V/s")


def test_train_prints_the_operating_point_of_its_test_split_first(
    trained: tuple[Path, str],
) -> None:
    """slipkit train of a detector opens its summary with the test split's operating point."""
    run, printed = trained
    metrics = json.loads((run / "metrics.json").read_text())
    expected = operating_point_line(metrics["name"], metrics["test"], metrics["unit"])
    assert expected == printed.splitlines()[0]


def test_evaluate_prints_the_operating_point_first_and_writes_it(
    run: Path, tmp_path: Path, unseen: Dataset, capsys: pytest.CaptureFixture[str]
) -> None:
    """slipkit evaluate prints the operating point before any AUC and keeps it in metrics.json."""
    folder = save_dataset(unseen, tmp_path / "ds")
    capsys.readouterr()
    out = _evaluate(run, folder)
    printed = capsys.readouterr().out.splitlines()
    ev = json.loads(out.read_text())
    point = ev["test"]["operating_point"]
    chosen = read_run(run).metrics["operating_point"]
    assert operating_point_line(ev["name"], ev["test"], ev["unit"]) == printed[0]
    # scored at the run's chosen threshold and debounce, on every trial of the data
    assert (chosen["threshold"], chosen["debounce_k"], 2) == (
        point["threshold"],
        point["debounce_k"],
        point["event_trials"],
    )


def test_summary_without_onsets_points_to_the_operating_points_trial_events() -> None:
    """Slip-or-wiggle labels (no onset): the threshold-level trial line has no slip to
    count, so it says where the slips are scored instead of printing 0/0."""
    from slipkit.train.tasks.detection_report import _summary_block

    rates = {"tpr": math.nan, "tnr": 0.99, "fpr": 0.01, "fnr": math.nan}
    block = {
        "estimator": "PinContactDetector",
        "stream": "camera_0",
        "threshold_from": "validation",
        "test": {
            "threshold": 0.19,
            "samples": {"auc": math.nan, **rates},
            "events": {
                "auc": math.nan,
                "sensitivity": math.nan,
                "specificity": 0.99,
                "tp": 0,
                "n_events": 0,
                "fp": 3,
                "n_negative_windows": 300,
            },
            "trials": {"n": 41, "n_slip": 0, "tp": 0, "fp": 11},
            "latency_ms": {"mean": math.nan, "sd": math.nan},
            "operating_point": {"unknown_onset_trials": 12},
        },
    }
    lines = _summary_block("gelsight_contact", block, None)
    assert lines[-1] == (
        "  test trials: no slip onsets (12 slip trials scored on detection only, at "
        "the operating point above)"
    )
    block["test"]["operating_point"] = {"unknown_onset_trials": 0}
    assert _summary_block("x", block, None)[-1].startswith("  test trials: 0/0 slips")
