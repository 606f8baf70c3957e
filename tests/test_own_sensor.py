"""docs/own-sensor.md end to end: a CSV of an unknown sensor -> dataset -> comparison -> bundle -> runtime."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from slipkit.baselines.generic import ChannelChangeDetector
from slipkit.cli import main
from slipkit.data.importers.csv import read_csv_dataset
from slipkit.export import export
from slipkit.export.detectors import check_detector_parity
from slipkit.models.window_detector import WindowClassifierDetector
from slipkit.train.tasks.detection import StreamDetection


def write_csvs(folder: Path, n_trials: int = 12, rate_hz: float = 200.0) -> Path:
    """One CSV per trial: ``t``, a pressure that sinks and a vibration that gets noisy
    after the trial's ``slip_onset_s`` (a sensor slipkit has no model of)."""
    folder.mkdir(parents=True)
    for k in range(n_trials):
        r = np.random.default_rng(k)
        n = 400
        t = np.arange(n) / rate_hz
        onset = r.uniform(0.8, 1.5)
        pressure = 1.0 + r.normal(0, 0.01, n)
        vibration = 50 + r.normal(0, 0.5, n)
        after = t >= onset
        pressure[after] -= 0.015 * np.sqrt(np.arange(after.sum()))
        vibration[after] += r.normal(0, 3.0, after.sum())
        lines = ["t,pressure,vibration,slip_onset_s"] + [
            f"{t[i]:.4f},{pressure[i]:.5f},{vibration[i]:.4f},{onset:.4f}"
            for i in range(n)
        ]
        (folder / f"trial{k:02d}.csv").write_text("\n".join(lines) + "\n")
    return folder


def test_generic_detectors_fit_score_and_export_on_an_imported_csv(
    tmp_path: Path,
) -> None:
    """Core of the walk in-process: the CSV importer's dataset, both generic detectors through
    the stream-detection task: every test slip caught, no early alarm, graphs in parity."""
    ds = read_csv_dataset(
        write_csvs(tmp_path / "csvs", n_trials=8),
        sensor="generic",
        time_column="t",
        rate_hz=200.0,
        label_columns=["slip_onset_s"],
    )
    task = StreamDetection(
        stream="signal", roc_unit="sample", negative_window_s=0.1, name="own"
    )
    train = ds.subset(ds.trial_ids[:4])
    test = ds.subset(ds.trial_ids[4:])
    rec_tr = task.recordings(train, "signal", None)
    rec_te = task.recordings(test, "signal", None)
    for det in (ChannelChangeDetector(feature="energy"), WindowClassifierDetector()):
        task._fit_one(det, rec_tr)
        metrics, _, _ = task.score(det, rec_te)
        # Every test slip caught, no alarm before an onset, slips outscore non-slip time.
        assert (4, 0, 1.0) == (
            metrics["trials"]["tp"],
            metrics["trials"]["fp"],
            metrics["events"]["auc"],
        )
        report = check_detector_parity(
            det, export(det), rec_te.X, segments=rec_te.segments
        )
        assert True is report["passed"]


@pytest.mark.slow
def test_the_own_sensor_walk_runs_from_csv_to_runtime(tmp_path: Path) -> None:
    """slipkit import -> slipkit compare comparison=own_sensor -> slipkit export -> slipkit-run
    replays the bundle: every step of docs/own-sensor.md succeeds and the learned and analytic
    estimators land in one report."""
    from slipkit.runtime.cli import run

    csvs = write_csvs(tmp_path / "csvs")
    ds, cmp, bundle = tmp_path / "ds", tmp_path / "cmp", tmp_path / "bundle"
    main(
        [
            "import",
            "source=csv",
            f"path={csvs}",
            f"out={ds}",
            "source.time_column=t",
            "source.rate_hz=200",
            "source.label_columns=[slip_onset_s]",
        ]
    )
    main(
        [
            "compare",
            "comparison=own_sensor",
            f"comparison.dataset.path={ds}",
            f"out={cmp}",
            "progress=false",
        ]
    )
    report = (cmp / "report.md").read_text()
    for est in ("derivative", "energy", "window_logreg", "window_mlp"):
        assert f"| {est} |" in report
    main(["export", f"run={cmp / 'runs' / 'window_logreg'}", f"out={bundle}"])
    summary = tmp_path / "run.json"
    assert 0 == run([str(bundle), "--json", str(summary)])
    out = json.loads(summary.read_text())
    assert out["decisions"] > 0
