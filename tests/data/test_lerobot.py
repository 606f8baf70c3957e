"""Datasets out: a slipkit dataset written in the LeRobot v3.0 layout, read back with
pyarrow / pandas, with slipkit's own reader, and (slow, where it installs) with the
standalone lerobot-dataset package; `slipkit export-dataset` refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from slipkit.cli import main
from slipkit.data import Dataset, LabelSpec, StreamSpec, load_dataset, save_dataset
from slipkit.data.lerobot import read_lerobot, write_lerobot
from slipkit.errors import SlipkitError

LENGTHS = (5, 8, 3)
CHANNELS = ("e1", "e2", "e3")


def tactile(rate_hz: float = 100.0, extra: bool = False) -> Dataset:
    """Three trials of a 3-channel stream (jittered times), labels and a group; with
    ``extra`` also a 2 kHz stream and a snapshot stream."""
    rng = np.random.default_rng(0)
    ids = [f"run{k}" for k in range(len(LENGTHS))]
    parts = []
    for tid, n in zip(ids, LENGTHS, strict=True):
        t = np.arange(n) / rate_hz + rng.uniform(0, 1e-4, n)
        part = pd.DataFrame(rng.normal(size=(n, 3)), columns=list(CHANNELS))
        part.insert(0, "t", t)
        part.insert(0, "trial_id", tid)
        parts.append(part)
    streams = {
        "taxels": StreamSpec(
            "taxels", CHANNELS, dict.fromkeys(CHANNELS, "kPa"), rate_hz
        )
    }
    tables = {"taxels": pd.concat(parts, ignore_index=True)}
    if extra:
        streams["pac"] = StreamSpec("pac", ("pac",), {"pac": "ADC"}, 2000.0)
        tables["pac"] = pd.DataFrame(
            {
                "trial_id": np.repeat(ids, 4),
                "t": np.tile(np.arange(4) / 2000.0, 3),
                "pac": 1.0,
            }
        )
        streams["grip"] = StreamSpec("grip", ("f",), {"f": "N"}, None, kind="snapshot")
        tables["grip"] = pd.DataFrame({"trial_id": ids, "t": 0.0, "f": [1.0, 2.0, 3.0]})
    trials = pd.DataFrame(
        {
            "trial_id": ids,
            "object": ["cube", "ball", "cube"],
            "slip_onset_s": [0.02, np.nan, 0.01],
            "slip_class": ["linear", "touch", "linear"],
        }
    )
    return Dataset(
        sensor="biotac",
        streams=streams,
        trials=trials,
        tables=tables,
        labels={
            "slip_onset_s": LabelSpec("slip_onset_s", unit="s"),
            "slip_class": LabelSpec("slip_class", classes=("linear", "touch")),
        },
        groups=("object",),
        name="tactile",
    )


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    return save_dataset(tactile(), tmp_path / "ds")


def test_layout_is_lerobot_v3(folder: Path, tmp_path: Path) -> None:
    """info.json, the data file, episodes, tasks and stats follow LeRobot v3.0."""
    out = write_lerobot(folder, tmp_path / "lr")
    info = json.loads((out / "meta/info.json").read_text())
    assert ("v3.0", 100, 3, 16, 1) == (
        info["codebase_version"],
        info["fps"],
        info["total_episodes"],
        info["total_frames"],
        info["total_tasks"],
    )
    assert {"dtype": "float64", "shape": [3], "names": list(CHANNELS)} == info[
        "features"
    ]["observation.taxels"]
    assert (
        "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
        == info["data_path"]
    )
    assert {"train": "0:3"} == info["splits"]
    data = pq.read_table(out / "data/chunk-000/file-000.parquet").to_pandas()
    assert list(range(16)) == data["index"].tolist()
    assert [0] * 5 + [1] * 8 + [2] * 3 == data["episode_index"].tolist()
    assert [*range(5), *range(8), *range(3)] == data["frame_index"].tolist()
    assert {0} == set(data["task_index"])
    episodes = pd.read_parquet(out / "meta/episodes/chunk-000/file-000.parquet")
    assert [[0, 5], [5, 13], [13, 16]] == episodes[
        ["dataset_from_index", "dataset_to_index"]
    ].to_numpy().tolist()
    assert ["run0", "run1", "run2"] == episodes["slipkit/trial_id"].tolist()
    tasks = pd.read_parquet(out / "meta/tasks.parquet")
    assert (["biotac recording"], [0]) == (
        tasks.index.tolist(),
        tasks["task_index"].tolist(),
    )
    stats = json.loads((out / "meta/stats.json").read_text())
    values = np.stack(data["observation.taxels"].to_numpy())
    np.testing.assert_allclose(values.mean(axis=0), stats["observation.taxels"]["mean"])
    np.testing.assert_allclose(values.std(axis=0), stats["observation.taxels"]["std"])
    assert [16] == stats["observation.taxels"]["count"]
    assert [15] == stats["index"]["max"]


def test_round_trip_keeps_values_labels_and_groups(
    folder: Path, tmp_path: Path
) -> None:
    """slipkit -> LeRobot -> slipkit: equal channels, labels and groups; t as float32."""
    before = load_dataset(folder)
    after = read_lerobot(write_lerobot(folder, tmp_path / "lr"))
    a, b = before.stream("taxels"), after.stream("taxels")
    assert a["trial_id"].tolist() == b["trial_id"].tolist()
    np.testing.assert_array_equal(
        a[list(CHANNELS)].to_numpy(), b[list(CHANNELS)].to_numpy()
    )
    np.testing.assert_array_equal(
        a["t"].to_numpy().astype(np.float32).astype(np.float64), b["t"].to_numpy()
    )
    pd.testing.assert_frame_equal(before.trials, after.trials, check_dtype=False)
    assert (before.labels, before.groups, before.streams["taxels"]) == (
        after.labels,
        after.groups,
        after.streams["taxels"],
    )


def test_fps_is_the_rate_rounded_and_stream_is_picked(tmp_path: Path) -> None:
    """Several sampled streams need stream=...; a 99.7 Hz stream is written at 100 fps."""
    src = save_dataset(tactile(rate_hz=99.7, extra=True), tmp_path / "ds")
    with pytest.raises(
        SlipkitError,
        match=r"has 2 sampled streams \(pac \(2000 Hz\), taxels \(99\.7 Hz\)\); a "
        r"LeRobot dataset has one fps, so pick one with stream=<name>$",
    ):
        write_lerobot(src, tmp_path / "lr")
    with pytest.raises(
        SlipkitError, match=r"stream=grip: is a snapshot stream without a rate"
    ):
        write_lerobot(src, tmp_path / "lr", stream="grip")
    out = write_lerobot(
        src, tmp_path / "lr", stream="taxels", feature="observation.state"
    )
    info = json.loads((out / "meta/info.json").read_text())
    marker = json.loads((out / "meta/slipkit.json").read_text())
    assert (100, 99.7, ["observation.state"]) == (
        info["fps"],
        marker["rate_hz"],
        [k for k in info["features"] if k.startswith("observation")],
    )
    assert [] == [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


# -- slipkit export-dataset ----------------------------------------------------------------
def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    captured = capsys.readouterr()
    return code, (captured.err if code else captured.out).strip().splitlines()


def test_cli_writes_and_overwrites_only_its_own(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit export-dataset` writes, refuses an existing out, replaces its own with
    overwrite=true and never a folder of anything else."""
    out = tmp_path / "lr"
    args = ["export-dataset", f"dataset={folder}", f"out={out}"]
    code, lines = run(args, capsys)
    assert (0, str(out)) == (code, lines[-1])
    assert (
        "LeRobot v3.0: 3 episodes, 16 frames at 100 fps, feature observation.taxels (3 channels)"
        == lines[0]
    )
    code, lines = run(args, capsys)
    assert (
        2,
        [
            f"slipkit export-dataset: error: out={out}: already exists (pass overwrite=true to replace it)"
        ],
    ) == (code, lines)
    assert 0 == run([*args, "overwrite=true"], capsys)[0]
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "notes.txt").write_text("mine")
    code, lines = run(
        ["export-dataset", f"dataset={folder}", f"out={docs}", "overwrite=true"], capsys
    )
    assert (2, "mine") == (code, (docs / "notes.txt").read_text())
    assert lines[0].endswith(
        f"out={docs}: exists and is not a slipkit lerobot; refusing to replace it"
    )


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["format=rlds"], "format=rlds: expected one of lerobot"),
        (["stream=nope"], "stream=nope: no such stream in"),
        (["feature=obs/taxels"], "feature=obs/taxels: expected a name without '/'"),
        (["verify=maybe"], "verify=maybe: expected true or false"),
    ],
)
def test_cli_bad_option_is_one_line_and_writes_nothing(
    folder: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    message: str,
) -> None:
    """A bad option ends in one line naming it, exit 2, and no output folder."""
    code, lines = run(
        ["export-dataset", f"dataset={folder}", f"out={tmp_path / 'lr'}", *extra],
        capsys,
    )
    assert (2, 1) == (code, len(lines))
    assert message in lines[0]
    assert ["ds"] == sorted(p.name for p in tmp_path.iterdir())


def test_cli_refuses_out_inside_the_dataset(
    folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An out inside the input dataset is refused before anything is written."""
    code, lines = run(
        ["export-dataset", f"dataset={folder}", f"out={folder / 'lr'}"], capsys
    )
    assert 2 == code
    assert f"out={folder / 'lr'}: is inside the input dataset={folder}" in lines[0]
    assert not (folder / "lr").exists()


# -- the standalone LeRobot reader ---------------------------------------------------------
@pytest.mark.slow
def test_lerobot_dataset_package_reads_it(folder: Path, tmp_path: Path) -> None:
    """The standalone lerobot-dataset package loads the export: episodes, frames, values."""
    try:
        from ledataset.datasets.lerobot_dataset import LeRobotDataset
    except Exception as exc:  # not installed, or its torchvision cannot load here
        pytest.skip(f"lerobot-dataset not importable: {type(exc).__name__}: {exc}")
    out = write_lerobot(folder, tmp_path / "lr")
    lr = LeRobotDataset("local/slipkit", root=out)
    expected = load_dataset(folder).stream("taxels")
    item = lr[6]  # episode 1, frame 1
    assert (3, 16, 100) == (lr.num_episodes, lr.num_frames, lr.fps)
    assert (1, 1, "biotac recording") == (
        int(item["episode_index"]),
        int(item["frame_index"]),
        item["task"],
    )
    # its torch loader turns the float64 values into float32 tensors
    np.testing.assert_array_equal(
        expected.iloc[6][list(CHANNELS)].to_numpy(np.float64).astype(np.float32),
        item["observation.taxels"].numpy(),
    )
