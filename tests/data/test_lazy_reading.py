"""Reading a dataset folder a chunk of trials at a time: the same trials, summary and
checks as loading it whole."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from tests.strategies import make_dataset

from slipkit._files import sha256_file
from slipkit.data import io as dio
from slipkit.data import load_dataset, save_dataset
from slipkit.data.summary import (
    format_summary,
    summarize,
    summary_dict,
    summary_of_folder,
)
from slipkit.errors import DatasetError


def _save_small_groups(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, **kwargs: int
) -> Path:
    """A dataset written with row groups of 1024 rows (the least), so a trial spans
    several of them."""
    monkeypatch.setattr(dio, "ROW_GROUP_VALUES", 1)
    return save_dataset(make_dataset(**kwargs), tmp_path / "ds")


def _rewrite(path: Path, rel: str, df: pd.DataFrame, row_group_size: int) -> None:
    df.to_parquet(path / rel, index=False, row_group_size=row_group_size)
    manifest = json.loads((path / "manifest.json").read_text())
    manifest["files"][rel] = sha256_file(path / rel)
    (path / "manifest.json").write_text(json.dumps(manifest))


def test_save_writes_row_groups_of_the_set_size(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A 3000-row stream written with 1024-row groups has 3 row groups."""
    path = _save_small_groups(tmp_path, monkeypatch, n_trials=10, n_frames=300)
    assert 3 == pq.ParquetFile(path / "streams" / "force.parquet").num_row_groups


def test_chunks_hold_every_trial_once_with_its_rows(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Chunks of about 4000 values (800 force rows) cover the trials in order, each
    trial's rows whole."""
    path = _save_small_groups(tmp_path, monkeypatch, n_trials=10, n_frames=300)
    whole = load_dataset(path)
    chunks = list(dio.iter_dataset_chunks(path, max_values=4000))
    assert 3 < len(chunks)
    assert whole.trial_ids == [t for c in chunks for t in c.trial_ids]
    for name, table in whole.tables.items():
        joined = pd.concat([c.tables[name] for c in chunks], ignore_index=True)
        pd.testing.assert_frame_equal(table, joined, check_dtype=False)


def test_folder_summary_equals_the_in_memory_summary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """summary_of_folder read in small chunks gives summary_dict of the loaded dataset."""
    path = _save_small_groups(tmp_path, monkeypatch, n_trials=9, n_frames=250)
    whole = load_dataset(path)
    expected = summary_dict(whole)
    actual = summary_of_folder(path, max_values=2000)
    assert expected == actual
    assert summarize(whole) == format_summary(actual)


def test_chunked_read_refuses_a_trial_split_across_the_file(tmp_path: Path) -> None:
    """A trial whose rows come back after another trial's is refused, naming the file,
    even when the two runs fall in different row groups."""
    path = save_dataset(make_dataset(n_trials=3, n_frames=100), tmp_path / "ds")
    force = pd.read_parquet(path / "streams" / "force.parquet")
    first = force[force["trial_id"] == "trial-000"]
    moved = pd.concat(
        [first.iloc[:50], force[force["trial_id"] != "trial-000"], first.iloc[50:]]
    )
    _rewrite(path, "streams/force.parquet", moved, row_group_size=50)
    with pytest.raises(DatasetError, match=r"force\.parquet.*not contiguous"):
        summary_of_folder(path, max_values=500)


def test_chunked_read_refuses_rows_of_unknown_trials(tmp_path: Path) -> None:
    """Stream rows naming a trial absent from trials.parquet are refused, not skipped."""
    path = save_dataset(make_dataset(n_trials=3, n_frames=100), tmp_path / "ds")
    force = pd.read_parquet(path / "streams" / "force.parquet")
    stray = force[force["trial_id"] == "trial-002"].assign(trial_id="ghost")
    _rewrite(
        path, "streams/force.parquet", pd.concat([force, stray]), row_group_size=64
    )
    with pytest.raises(DatasetError, match=r"force\.parquet.*not in trials.*ghost"):
        list(dio.iter_dataset_chunks(path, max_values=500))


def test_chunked_read_refuses_a_channel_never_finite_over_all_chunks(
    tmp_path: Path,
) -> None:
    """A channel that is NaN in every chunk is refused as load_dataset refuses it."""
    path = save_dataset(make_dataset(n_trials=4, n_frames=100), tmp_path / "ds")
    force = pd.read_parquet(path / "streams" / "force.parquet").assign(fy=np.nan)
    _rewrite(path, "streams/force.parquet", force, row_group_size=64)
    with pytest.raises(
        DatasetError, match=r"column 'fy' has no finite value in its 400"
    ):
        summary_of_folder(path, max_values=500)
    with pytest.raises(
        DatasetError, match=r"column 'fy' has no finite value in its 400"
    ):
        load_dataset(path)


def test_chunked_read_runs_the_dataset_checks_per_chunk(tmp_path: Path) -> None:
    """Time running backwards inside a trial is refused in the chunked read too."""
    path = save_dataset(make_dataset(n_trials=3, n_frames=100), tmp_path / "ds")
    force = pd.read_parquet(path / "streams" / "force.parquet")
    force.loc[250, "t"] = -1.0  # inside trial-002
    _rewrite(path, "streams/force.parquet", force, row_group_size=64)
    with pytest.raises(DatasetError, match=r"force\.parquet.*'t' decreases"):
        summary_of_folder(path, max_values=500)
