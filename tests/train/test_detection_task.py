"""StreamDetection task: labels, event and trial counts, and train + evaluate end to end."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from tests.strategies import make_dataset

from slipkit import config_dir
from slipkit.data import save_dataset
from slipkit.data.dataset import Dataset, LabelSpec, StreamSpec, Trial
from slipkit.errors import SlipkitError
from slipkit.families.biotac.detectors import ForceDerivative
from slipkit.sim.commands import build_scene
from slipkit.train.commands import evaluate_main, train_main
from slipkit.train.tasks.detection import Recordings, StreamDetection


def recordings(y: list[int], rate: float = 100.0) -> Recordings:
    """One trial of ``len(y)`` samples with the given per-sample labels."""
    n = len(y)
    yy = np.asarray(y, dtype=int)
    onset = float(np.argmax(yy) / rate) if yy.any() else float("nan")
    return Recordings(
        X=np.zeros((n, 1)),
        y=yy,
        t=np.arange(n) / rate,
        segments=np.zeros(n, dtype=int),
        trial_ids=["a"],
        groups=[""],
        onset_s=np.array([onset]),
        reference_s=np.array([onset + 0.05]),
        disturbance=None,
        rate_hz=rate,
    )


def test_event_units_cut_non_slip_time_into_windows() -> None:
    """Two events are two positives; the 10 other samples make 5 two-sample negatives."""
    task = StreamDetection(stream="s", label="slip_onset_s", negative_window_s=0.02)
    rec = recordings([0, 0, 0, 0, 1, 1, 0, 0, 0, 1, 0, 0, 0, 0])
    scores = np.arange(14, dtype=float)
    labels, best, _ = task.event_units(rec, scores)
    assert [1, 1, 0, 0, 0, 0, 0, 0] == labels.tolist()
    assert [5.0, 9.0, 1.0, 3.0, 7.0, 8.0, 11.0, 13.0] == best.tolist()


def test_trial_table_counts_early_fires_detections_and_latency() -> None:
    """Firing before the onset is a false positive; latency runs from the onset (ms)."""
    task = StreamDetection(stream="s", label="slip_onset_s")
    rec = recordings([0] * 10 + [1] * 10)
    pred = np.zeros(20, dtype=bool)
    pred[[3, 13]] = True
    row = task._trial_table(rec, pred).iloc[0]
    assert bool(row["fired_before"])
    assert bool(row["detected"])
    assert 30.0 == pytest.approx(row["latency_ms"])
    assert -20.0 == pytest.approx(row["vs_reference_ms"])


def test_missing_stream_and_channel_are_named() -> None:
    """A stream or channel the dataset lacks is a SlipkitError naming it."""
    ds = make_dataset(n_trials=2, n_frames=50)
    task = StreamDetection(stream="force", channels=["fx", "nope"])
    with pytest.raises(SlipkitError, match="nope"):
        task.recordings(ds, "force", ["fx", "nope"])
    with pytest.raises(SlipkitError, match="pac"):
        task.recordings(ds, "pac", None)


def test_truth_column_labels_are_looked_up_across_rates() -> None:
    """Labels from a 300 Hz truth column land on the 2.2 kHz pac samples by time."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=biotac_lift_slip"])
    ds = build_scene(cfg.scene).simulate(1, seed=1)
    task = StreamDetection(
        stream="pac", truth_stream="truth_force", truth_column="ft", label=None
    )
    rec = task.recordings(ds, "pac", ["pac"])
    ft = next(iter(ds)).streams["truth_force"]
    expected = ft["t"].to_numpy()[np.argmax(ft["ft"].to_numpy() > 0)]
    assert expected == pytest.approx(rec.t[np.argmax(rec.y)], abs=1 / 300)


def compose_train(*overrides: str) -> object:
    """The train config with overrides."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name="train", overrides=list(overrides))


def test_fsr_roc_trains_and_evaluates(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """fsr_roc end to end: run folder with ROC plot; evaluate scores an unseen dataset."""
    run = tmp_path / "run"
    cfg = compose_train("experiment=fsr_roc", "dataset.n_trials=4", f"run_dir={run}")
    train_main(cfg)  # type: ignore[arg-type]
    printed = capsys.readouterr().out
    assert "paper 8" in printed
    assert (run / "roc.png").stat().st_size > 0
    metrics = json.loads((run / "metrics.json").read_text())
    assert (
        "lowest cost on validation: group k-fold by trial, k=2"
        == metrics["threshold_from"]
    )
    assert 0 == metrics["test"]["disturbances"]["fired"]
    from slipkit.train.runs import read_run

    assert metrics["threshold"] == read_run(run).model.threshold_
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        scfg = compose(config_name="simulate", overrides=["scene=fsr_probe_slide"])
    folder = save_dataset(build_scene(scfg.scene).simulate(2, seed=11), tmp_path / "ds")
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        ecfg = compose(
            config_name="evaluate",
            overrides=[f"run={run}", f"dataset={folder}", "name=unseen"],
        )
    out = evaluate_main(ecfg)
    ev = json.loads(out.read_text())
    assert 2 == ev["dataset"]["n_trials"]
    assert ev["test"]["events"]["n_events"] > 0


def test_biotac_slip_detect_reports_both_detectors(tmp_path: Path) -> None:
    """biotac_slip_detect: pressure leads the IMU onset and the force derivative lags it."""
    run = tmp_path / "run"
    cfg = compose_train(
        "experiment=biotac_slip_detect", "dataset.n_trials=4", f"run_dir={run}"
    )
    train_main(cfg)  # type: ignore[arg-type]
    m = json.loads((run / "metrics.json").read_text())
    fd = m["detectors"]["force_derivative"]
    assert "ForceDerivative" == fd["estimator"]
    assert m["test"]["vs_reference_ms"]["all"]["mean"] < 0
    assert fd["test"]["vs_reference_ms"]["all"]["mean"] > 0


def test_compare_entry_without_fixed_threshold_is_skipped_in_evaluate(
    tmp_path: Path,
) -> None:
    """A compare detector with a ROC-chosen threshold cannot be re-scored by evaluate."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=biotac_lift_slip"])
    ds = build_scene(cfg.scene).simulate(4, seed=2)
    task = StreamDetection(
        stream="truth_force",
        channels=["fx", "fy"],
        compare=[
            {
                "name": "free",
                "detector": ForceDerivative(threshold=None),
                "stream": "truth_force",
                "channels": ["fx", "fy"],
            }
        ],
    )
    result = task.fit(ForceDerivative(), ds, seed=0, out=tmp_path)
    assert "sample ROC" == result.metrics["detectors"]["free"]["threshold_from"]
    metrics = task.evaluate(result.model, ds, out=tmp_path)
    assert "skipped" in metrics["detectors"]["free"]


def test_detection_objective_is_a_validation_score_test_labels_cannot_move(
    tmp_path: Path,
) -> None:
    """Moving the test trials' onsets changes the test scores, not the validation objective."""
    from slipkit.data.dataset import Dataset
    from slipkit.data.splits import split_by_trial

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=biotac_lift_slip"])
    ds = build_scene(cfg.scene).simulate(6, seed=2)
    test_ids = split_by_trial(ds, test_size=0.5, seed=0).test
    trials = ds.trials.copy()
    trials.loc[trials["trial_id"].isin(test_ids), "slip_onset_s"] = 0.05
    moved = Dataset(
        sensor=ds.sensor,
        streams=ds.streams,
        trials=trials,
        tables=ds.tables,
        labels=ds.labels,
        groups=ds.groups,
        provenance=ds.provenance,
        name=ds.name,
    )
    task = StreamDetection(stream="truth_force", channels=["fx", "fy"], cv=3)
    clean = task.fit(ForceDerivative(), ds, seed=0, out=tmp_path).metrics
    bad = task.fit(ForceDerivative(), moved, seed=0, out=tmp_path).metrics
    assert ("group-kfold by trial", 3) == (
        clean["validation"]["cv"],
        clean["validation"]["k"],
    )
    assert clean["test"]["samples"]["auc"] != bad["test"]["samples"]["auc"]
    assert clean["validation"] == bad["validation"]
    assert task.objective_value(clean) == task.objective_value(bad)


# -- operating point on validation trials -------------------------------------------------


def _slip_dataset(n_trials: int = 12, n_objects: int = 3) -> Dataset:
    """Trials of a 100 Hz signal that jumps at the onset; every fourth trial a touch
    without slip (NaN onset and a ``slipped`` label of 0), objects cycling."""
    trials = []
    for i in range(n_trials):
        r = np.random.default_rng(i)
        t = np.arange(200) / 100.0
        slipped = i % 4 != 3
        onset = float(r.uniform(0.8, 1.2)) if slipped else math.nan
        x = r.normal(0.0, 0.1, 200)
        if slipped:
            x[t >= onset] += 3.0
        trials.append(
            Trial(
                f"tr{i:02d}",
                {"signal": pd.DataFrame({"t": t, "x": x})},
                labels={"slip_onset_s": onset, "slipped": float(slipped)},
                meta={"object": f"obj{i % n_objects}"},
            )
        )
    return Dataset.from_trials(
        trials,
        sensor="generic",
        streams={"signal": StreamSpec("signal", ("x",), {"x": "1"}, rate_hz=100.0)},
        labels={
            "slip_onset_s": LabelSpec("slip_onset_s", unit="s"),
            "slipped": LabelSpec("slipped"),
        },
        groups=("object",),
        name="slips",
    )


def _detection(**kw: object) -> StreamDetection:
    return StreamDetection(
        stream="signal",
        roc_unit="sample",
        negative_window_s=0.1,
        operating_point={"debounce": [1, 2, 3]},
        name="own",
        **kw,  # type: ignore[arg-type]
    )


def test_the_operating_point_is_chosen_on_training_trials_only(tmp_path: Path) -> None:
    """The recorded provenance: the point was chosen on exactly the training trials (by
    object folds), never on a test trial, and the test split was scored at it."""
    from slipkit.baselines.generic import ChannelChangeDetector

    result = _detection().fit(
        ChannelChangeDetector(feature="derivative"),
        _slip_dataset(),
        seed=0,
        out=tmp_path,
    )
    m = result.metrics
    op = m["operating_point"]
    assert (set(m["split"]["train"]), set()) == (
        set(op["chosen_on"]),
        set(op["chosen_on"]) & set(m["split"]["test"]),
    )
    assert "validation: group k-fold by object, k=3" == op["from"]
    assert (op["debounce_k"], len(m["split"]["test"])) == (
        m["test"]["operating_point"]["debounce_k"],
        m["test"]["operating_point"]["event_trials"],
    )


def test_split_by_group_keeps_each_object_on_one_side(tmp_path: Path) -> None:
    """split=auto on data with objects: every object on one side; the touches (slipped 0,
    NaN onset) are no-slip trials, not unknown ones."""
    from slipkit.baselines.generic import ChannelChangeDetector

    ds = _slip_dataset()
    result = _detection(split="auto", test_size=0.33).fit(
        ChannelChangeDetector(feature="derivative"), ds, seed=0, out=tmp_path
    )
    m = result.metrics
    obj = ds.trials.set_index("trial_id")["object"]
    train, test = set(obj[m["split"]["train"]]), set(obj[m["split"]["test"]])
    assert ("object", set(), 1) == (m["split_by"], train & test, len(test))
    table = pd.read_csv(tmp_path / "test_trials.csv")
    touches = table[table["slipped"] == False]  # noqa: E712
    assert (1, 0) == (len(touches), int(touches["onset_s"].notna().sum()))


def test_a_fixed_threshold_stays_and_only_the_debounce_is_chosen(
    tmp_path: Path,
) -> None:
    """A detector with threshold in its config keeps it; the debounce is still chosen."""
    from slipkit.baselines.generic import ChannelChangeDetector

    det = ChannelChangeDetector(feature="derivative", threshold=5.0)
    result = _detection().fit(det, _slip_dataset(), seed=0, out=tmp_path)
    op = result.metrics["operating_point"]
    assert (5.0, 5.0, True) == (
        op["threshold"],
        result.model.threshold_,
        op["debounce_k"] in (1, 2, 3),
    )


def test_export_deploys_the_runs_chosen_debounce(tmp_path: Path) -> None:
    """slipkit export with debounce_k=null writes the debounce the run chose on validation."""
    from slipkit.cli import main

    run = tmp_path / "run"
    cfg = compose_train(
        "experiment=fsr_roc",
        "dataset.n_trials=4",
        f"run_dir={run}",
        "task.operating_point.debounce=[3]",
    )
    train_main(cfg)  # type: ignore[arg-type]
    assert (
        3
        == json.loads((run / "metrics.json").read_text())["operating_point"][
            "debounce_k"
        ]
    )
    main(["export", f"run={run}", f"out={tmp_path / 'bundle'}", "choose_session=false"])
    manifest = json.loads((tmp_path / "bundle" / "manifest.json").read_text())
    assert {"k": 3} == manifest["debounce"]


def test_stratify_gives_the_sliptack_speed_split() -> None:
    """stratify=object splits by trial keeping each object's share, the same trials as
    the SlipTack speed task's split of the data (so a comparison can hold both)."""
    from slipkit.data.splits import split_by_trial

    ds = _slip_dataset()
    split, by = _detection(stratify="object").split_of(ds, 3)
    expected = split_by_trial(ds, test_size=0.5, seed=3, stratify="object")
    assert (expected.test, "trial") == (split.test, by)
