"""ForceRegression (30 s-block split, RMSE/SMSE, comparison) and FingerDirection (angle error)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from hydra import compose, initialize_config_dir
from hypothesis import given, settings
from hypothesis import strategies as st
from omegaconf import DictConfig

import slipkit
from slipkit.data.importers.robotic_finger import read_robotic_finger
from slipkit.data.io import save_dataset
from slipkit.errors import SlipkitError
from slipkit.families.biotac.direction_task import (
    FingerDirection,
    angle_errors_deg,
    contiguous_block_split,
)
from slipkit.families.biotac.force import LocalLinearRegressor, WeightedNormalsRegressor
from slipkit.families.biotac.force_task import ForceRegression
from slipkit.families.biotac.physics import linear_drive_matrix
from slipkit.sim.commands import build_scene
from slipkit.train.commands import evaluate_main, train_main

torch.set_num_threads(1)

#: Shrinks experiment=biotac_force to a few seconds: 3 short trials in 2 s blocks,
#: every 6th frame, a few epochs, few receptive fields.
SMALL_FORCE = [
    "dataset.n_trials=3",
    "scene.model.duration_s=12",
    "task.block_s=2",
    "task.stride=6",
    "model.max_epochs=3",
    "task.compare.mlp1.max_epochs=3",
    "task.compare.lwr.n_fields=5",
]


def train_cfg(*overrides: str) -> DictConfig:
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        return compose(config_name="train", overrides=list(overrides))


def evaluate_cfg(*overrides: str) -> DictConfig:
    with initialize_config_dir(
        config_dir=str(slipkit.config_dir()), version_base="1.3"
    ):
        return compose(config_name="evaluate", overrides=list(overrides))


def probe_dataset(n_trials: int = 3, duration_s: float = 12.0, seed: int = 0):
    cfg = train_cfg("experiment=biotac_force", f"scene.model.duration_s={duration_s}")
    return build_scene(cfg.scene).simulate(n_trials, seed)


def test_split_keeps_blocks_apart_and_covers_every_kept_frame():
    """Each block's frames lie on one side only; the sides cover every strided frame."""
    dataset = probe_dataset()
    task = ForceRegression(block_s=2.0, stride=4)
    frames = task.frames(dataset)
    sides, block = task.sides(dataset, frames, seed=3)
    owner = {
        name: set(block[mask].tolist())
        for name, mask in (
            ("train", sides.train),
            ("val", sides.val),
            ("test", sides.test),
        )
    }
    assert set() == owner["train"] & owner["test"]
    assert set() == owner["train"] & owner["val"]
    assert set() == owner["val"] & owner["test"]
    kept = task._strided(frames)
    np.testing.assert_array_equal(kept, sides.train | sides.val | sides.test)
    # a block never crosses trials and spans at most block_s seconds
    table = pd.DataFrame({"block": block, "trial": frames.trial, "t": frames.t})
    per_block = table.groupby("block").agg(
        trials=("trial", "nunique"), span=("t", lambda t: t.max() - t.min())
    )
    assert {1} == set(per_block["trials"])
    assert per_block["span"].max() < 2.0


def test_baseline_first_subtracts_the_unloaded_frames():
    """baseline='first' makes each trial's first frames zero on average; 'none' keeps counts."""
    dataset = probe_dataset(n_trials=1, duration_s=4.0)
    rel = ForceRegression(baseline="first", baseline_frames=5).frames(dataset)
    raw = ForceRegression(baseline="none").frames(dataset)
    assert abs(float(np.median(rel.X[:5]))) < 1.0
    assert float(np.median(raw.X[:5])) > 1000.0  # the 2000-count unloaded reading
    assert (19, 3) == (rel.X.shape[1], rel.y.shape[1])
    with_pdc = ForceRegression(pdc_stream="pdc").frames(dataset)
    assert 20 == with_pdc.X.shape[1]


def test_force_task_refuses_missing_streams_and_too_few_blocks(tmp_path: Path):
    """A missing stream or channel, or too few blocks, is a SlipkitError saying which."""
    dataset = probe_dataset(n_trials=1, duration_s=4.0)
    with pytest.raises(SlipkitError, match="no stream 'forces'"):
        ForceRegression(target="forces").frames(dataset)
    with pytest.raises(SlipkitError, match=r"no channel\(s\) \['ft'\]"):
        ForceRegression(axes=("fx", "ft")).frames(dataset)
    with pytest.raises(SlipkitError, match=r"task\.block_s=30"):
        ForceRegression().fit(WeightedNormalsRegressor(), dataset, seed=0, out=tmp_path)


def test_trials_shorter_than_a_block_become_whole_blocks(tmp_path: Path):
    """With trials shorter than block_s, blocks are trials and the summary says so."""
    dataset = probe_dataset(n_trials=6, duration_s=3.0)
    result = ForceRegression(block_s=30.0, stride=5).fit(
        WeightedNormalsRegressor(), dataset, seed=0, out=tmp_path
    )
    assert result.metrics["split"]["blocks_are_trials"]
    assert 6 == sum(result.metrics["split"]["blocks"].values())
    assert "each block is a whole trial" in result.summary[1]


def test_train_and_evaluate_biotac_force_end_to_end(tmp_path: Path):
    """slipkit train experiment=biotac_force (shrunk) writes per-axis metrics and the
    comparison; slipkit evaluate scores an unseen simulated dataset."""
    run = tmp_path / "run"
    objective = train_main(
        train_cfg("experiment=biotac_force", *SMALL_FORCE, f"run_dir={run}")
    )
    metrics = json.loads((run / "metrics.json").read_text())
    for side in ("full", "train", "val", "test"):
        assert ["x", "y", "z"] == list(metrics[side]["rmse"])
        assert ["x", "y", "z"] == list(metrics[side]["smse"])
    assert objective == pytest.approx(metrics["validation"]["rmse_mean"])
    assert 3 == len(metrics["validation"]["folds"])
    assert ["mlp3", "normals", "mlp1", "lwr"] == list(metrics["comparison"])
    table = pd.read_csv(run / "comparison.csv", index_col="model")
    assert ["mlp3", "normals", "mlp1", "lwr"] == list(table.index)
    assert {"rmse_x_full", "smse_z_full", "rmse_x_test", "smse_z_test"} <= set(
        table.columns
    )
    assert (run / "force_test.png").stat().st_size > 0
    assert "paper 3-layer NN" in (run / "comparison.md").read_text()

    unseen = tmp_path / "unseen"
    save_dataset(probe_dataset(n_trials=1, duration_s=4.0, seed=99), unseen)
    out = evaluate_main(evaluate_cfg(f"run={run}", f"dataset={unseen}", "name=u"))
    scored = json.loads(out.read_text())
    assert not scored["dataset"]["seen_in_training"]
    assert ["x", "y", "z"] == list(scored["test"]["rmse"])
    assert scored["test"]["n"] > 0


@settings(max_examples=30, deadline=None)
@given(
    angle=st.floats(0.0, 180.0),
    scale=st.floats(1e-3, 1e3),
    axis=st.integers(0, 2),
)
def test_angle_error_is_the_rotation_angle_and_ignores_the_length(
    angle: float, scale: float, axis: int
):
    """A truth rotated by theta, at any length, is theta degrees away."""
    truth = np.eye(3)[[axis]]
    other = np.eye(3)[[(axis + 1) % 3]]
    rad = np.deg2rad(angle)
    pred = scale * (np.cos(rad) * truth + np.sin(rad) * other)
    assert angle_errors_deg(pred, truth)[0] == pytest.approx(angle, abs=1e-5)


def test_angle_error_of_a_zero_prediction_is_ninety_degrees():
    """A zero vector has no direction and counts as orthogonal."""
    assert [90.0] == angle_errors_deg(
        np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]])
    ).tolist()


def write_synthetic_finger(path: Path, n: int = 400, seed: int = 0) -> Path:
    """Robotic-Finger layout (X1.txt 19 x n, Y1.txt 3 x n) from the linear electrode
    response, forces within 40 deg of the pad normal, electrodes mean-centred."""
    rng = np.random.default_rng(seed)
    tilt = np.deg2rad(rng.uniform(0.0, 40.0, n))
    az = rng.uniform(0.0, 2.0 * np.pi, n)
    u = np.column_stack(
        [np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)]
    )
    force = u * rng.uniform(1.0, 8.0, (n, 1))
    e = force @ linear_drive_matrix(60.0).T + rng.normal(0.0, 1.0, (n, 19))
    e -= e.mean(axis=0)
    path.mkdir()
    np.savetxt(path / "X1.txt", e.T)
    np.savetxt(path / "Y1.txt", u.T)
    return path


def test_finger_direction_beats_a_constant_on_a_synthetic_snapshot_dataset(
    tmp_path: Path,
):
    """On a linear response, weighted normals predict the direction at least twice as
    well as the constant mean direction; compare rows and evaluate work."""
    dataset = read_robotic_finger(write_synthetic_finger(tmp_path / "finger"))
    task = FingerDirection(
        model_name="normals",
        compare={"lwr": LocalLinearRegressor(n_fields=5, random_state=0)},
    )
    result = task.fit(WeightedNormalsRegressor(), dataset, seed=0, out=tmp_path)
    m = result.metrics
    assert (400, "trial (sample), random") == (
        m["split"]["train"] + m["split"]["val"] + m["split"]["test"],
        m["split"]["by"],
    )
    # Scales fitted to unit targets are not exactly equal across axes, so a few
    # degrees remain; the constant is off by the 40 deg cone's spread.
    assert (
        m["test"]["angle_mean_deg"]
        < 0.5 * (m["constant_mean_direction"]["test"]["angle_mean_deg"])
    )
    table = pd.read_csv(tmp_path / "comparison.csv", index_col="model")
    assert ["normals", "lwr", "constant mean direction"] == list(table.index)
    scored = task.evaluate(result.model, dataset, out=tmp_path)
    assert 400 == scored["test"]["n"]


def test_train_finger_direction_end_to_end_on_a_synthetic_recording(tmp_path: Path):
    """slipkit train experiment=finger_direction reads a Robotic-Finger folder and
    reports train/test angle errors beside the constant baseline."""
    raw = write_synthetic_finger(tmp_path / "robotic-finger", n=300)
    run = tmp_path / "run"
    train_main(
        train_cfg(
            "experiment=finger_direction",
            f"dataset.raw={raw}",
            f"run_dir={run}",
            "model.max_epochs=3",
            "task.compare.mlp1.max_epochs=3",
            "task.compare.lwr.n_fields=5",
        )
    )
    metrics = json.loads((run / "metrics.json").read_text())
    assert {"angle_mean_deg", "angle_median_deg"} <= set(metrics["test"])
    assert {"train", "test"} <= set(metrics["constant_mean_direction"])


@pytest.mark.realdata
def test_finger_direction_on_the_real_recordings(shared_data: Path, tmp_path: Path):
    """On the real Robotic-Finger data, weighted normals beat the constant direction."""
    folder = shared_data / "robotic-finger"
    if not folder.is_dir():
        pytest.skip(f"{folder} not present")
    result = FingerDirection().fit(
        WeightedNormalsRegressor(), read_robotic_finger(folder), seed=0, out=tmp_path
    )
    m = result.metrics
    assert (
        m["test"]["angle_mean_deg"]
        < m["constant_mean_direction"]["test"]["angle_mean_deg"]
    )


@given(
    n=st.integers(5, 400),
    test_size=st.floats(0.05, 0.5),
    val_size=st.floats(0.0, 0.4),
    seed=st.integers(0, 20),
)
def test_block_split_holds_out_one_contiguous_block(
    n: int, test_size: float, val_size: float, seed: int
):
    """The test side is one run of consecutive samples; the three sides partition them."""
    tr, va, te = contiguous_block_split(
        np.arange(n), test_size=test_size, val_size=val_size, seed=seed
    )
    assert int(np.ceil(test_size * n)) == len(te)
    assert list(range(te[0], te[0] + len(te))) == te.tolist()
    assert list(range(n)) == sorted([*tr, *va, *te])
    assert len(tr) >= 1


def _with_test_directions_flipped(dataset, ids):
    """``dataset`` with the direction of the samples ``ids`` reversed (wrong targets)."""
    from slipkit.data.dataset import Dataset

    tables = dict(dataset.tables)
    t = tables["truth_force_dir"].copy()
    rows = t["trial_id"].isin(ids)
    t.loc[rows, ["ux", "uy", "uz"]] *= -1.0
    tables["truth_force_dir"] = t
    return Dataset(
        sensor=dataset.sensor,
        streams=dataset.streams,
        trials=dataset.trials,
        tables=tables,
        labels=dataset.labels,
        groups=dataset.groups,
        provenance=dataset.provenance,
        name=dataset.name,
    )


def test_finger_direction_block_split_reports_both_and_keeps_test_out_of_validation(
    tmp_path: Path,
):
    """Block split: scores of both splits; flipping the test targets changes test, not validation."""
    dataset = read_robotic_finger(write_synthetic_finger(tmp_path / "finger", n=200))
    task = FingerDirection(split="block", also_split=("random",), model_name="normals")
    clean = task.fit(WeightedNormalsRegressor(), dataset, seed=0, out=tmp_path).metrics
    assert ("contiguous block", {"block", "random"}) == (
        clean["split"]["by"],
        set(clean["splits"]),
    )
    order = np.arange(200)
    _, _, te = contiguous_block_split(order, test_size=0.2, val_size=0.2, seed=0)
    ids = [f"sample{k:04d}" for k in te]
    flipped = _with_test_directions_flipped(dataset, ids)
    bad = task.fit(WeightedNormalsRegressor(), flipped, seed=0, out=tmp_path).metrics
    assert clean["test"]["angle_mean_deg"] != bad["test"]["angle_mean_deg"]
    assert clean["validation"] == bad["validation"]
    assert task.objective_value(clean) == task.objective_value(bad)


@pytest.mark.realdata
def test_finger_direction_block_split_on_the_real_recordings(
    shared_data: Path, tmp_path: Path
):
    """On the real data the held-out block is harder than random samples, yet the
    weighted normals still beat the constant direction on it."""
    folder = shared_data / "robotic-finger"
    if not folder.is_dir():
        pytest.skip(f"{folder} not present")
    task = FingerDirection(split="block", also_split=("random",), cv=0)
    m = task.fit(
        WeightedNormalsRegressor(), read_robotic_finger(folder), seed=0, out=tmp_path
    ).metrics
    block = m["splits"]["block"]
    assert "contiguous block" == block["by"]
    assert (
        m["test"]["angle_mean_deg"]
        < block["constant_mean_direction"]["test"]["angle_mean_deg"]
    )
