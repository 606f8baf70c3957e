"""The Dataset/Trial contract and the on-disk format: round trips, checks and atomic writes."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.strategies import FORCE, LABELS, make_dataset

from slipkit._files import sha256_file
from slipkit.data import (
    SCHEMA_VERSION,
    Dataset,
    LabelSpec,
    StreamSpec,
    Trial,
    load_dataset,
    save_dataset,
)
from slipkit.data import io as dio
from slipkit.errors import DatasetError, SlipkitError


def _rewrite(path: Path, rel: str, df: pd.DataFrame) -> None:
    """Replace a table and fix its checksum, so that only the content check can fail."""
    df.to_parquet(path / rel, index=False)
    manifest = json.loads((path / "manifest.json").read_text())
    manifest["files"][rel] = sha256_file(path / rel)
    (path / "manifest.json").write_text(json.dumps(manifest))


def _edit_manifest(path: Path, **changes: object) -> None:
    manifest = json.loads((path / "manifest.json").read_text())
    manifest.update(changes)
    (path / "manifest.json").write_text(json.dumps(manifest))


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    return save_dataset(make_dataset(), tmp_path / "ds")


def test_round_trip_keeps_tables_specs_and_fingerprint(tmp_path: Path) -> None:
    """Saving then loading gives the same trials, streams, labels, groups and fingerprint."""
    ds = make_dataset()
    loaded = load_dataset(save_dataset(ds, tmp_path / "ds"))
    assert ds.fingerprint() == loaded.fingerprint()
    assert ds.streams == loaded.streams
    assert ds.labels == loaded.labels
    assert ds.groups == loaded.groups
    pd.testing.assert_frame_equal(ds.trials, loaded.trials, check_dtype=False)
    for name in ds.tables:
        pd.testing.assert_frame_equal(
            ds.tables[name], loaded.tables[name], check_dtype=False
        )
    assert {"scene": "unit-test", "seed": 0} == loaded.provenance


def test_iterating_yields_trials_with_streams_labels_and_meta() -> None:
    """Each Trial carries its own rows only, its scalar labels and its group values."""
    ds = make_dataset(n_trials=4, n_frames=50)
    trials = list(ds)
    assert ["trial-000", "trial-001", "trial-002", "trial-003"] == [
        t.trial_id for t in trials
    ]
    first = trials[1]
    assert ["t", "fx", "fy", "fz"] == list(first.streams["force"].columns)
    assert 50 == len(first.streams["force"])
    assert "rotational" == first.labels["slip_class"]
    assert {"object": "obj1", "sensor": "biotac"} == first.meta
    assert pytest.approx(49 / 300) == first.duration_s()
    assert first.trial_id == ds["trial-001"].trial_id


def test_to_frames_joins_labels_onto_stream_rows() -> None:
    """to_frames gives pandas tables with trial labels and groups on every stream row."""
    ds = make_dataset(n_trials=3, n_frames=10, with_events=False)
    trials, streams = ds.to_frames()
    assert 3 == len(trials)
    assert {
        "trial_id",
        "t",
        "fx",
        "fy",
        "fz",
        "object",
        "slip_class",
        "slip_onset_s",
    } == set(streams["force"].columns)
    assert 30 == len(streams["force"])


def test_same_content_gives_byte_identical_files(tmp_path: Path) -> None:
    """Writing the same dataset twice gives identical bytes in every file (reproducible runs)."""
    a = save_dataset(make_dataset(seed=3), tmp_path / "a")
    b = save_dataset(make_dataset(seed=3), tmp_path / "b")
    for rel in [
        "manifest.json",
        "trials.parquet",
        "streams/force.parquet",
        "streams/events.parquet",
    ]:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel


def test_manifest_lists_schema_rates_units_and_checksums(saved: Path) -> None:
    """manifest.json names the format, schema, sensor, stream rates and units, and each file's sha256."""
    manifest = json.loads((saved / "manifest.json").read_text())
    assert "slipkit-dataset" == manifest["format"]
    assert SCHEMA_VERSION == manifest["schema_version"]
    assert 300.0 == manifest["streams"]["force"]["rate_hz"]
    assert manifest["streams"]["events"]["rate_hz"] is None
    assert {"fx": "N", "fy": "N", "fz": "N"} == manifest["streams"]["force"]["units"]
    assert (
        sha256_file(saved / "streams/force.parquet")
        == manifest["files"]["streams/force.parquet"]
    )


def test_subset_keeps_only_named_trials() -> None:
    """subset() keeps the named trials' rows in every stream and nothing else."""
    ds = make_dataset(n_trials=5)
    sub = ds.subset(["trial-001", "trial-003"])
    assert ["trial-001", "trial-003"] == sub.trial_ids
    assert {"trial-001", "trial-003"} == set(sub.stream("force")["trial_id"])
    with pytest.raises(KeyError, match="trial-999"):
        ds.subset(["trial-999"])


# -- checks on load: every error names the file and the field ----------------------------


def test_checksum_mismatch_names_the_file(saved: Path) -> None:
    """A modified stream file is refused, naming the file and the sha256 mismatch."""
    with open(saved / "streams/force.parquet", "ab") as fh:
        fh.write(b"tampered")
    with pytest.raises(DatasetError, match=r"streams/force\.parquet: sha256 mismatch"):
        load_dataset(saved)


def test_truncated_parquet_names_the_file(saved: Path) -> None:
    """A truncated Parquet file is reported as unreadable with its path (checksums off)."""
    path = saved / "streams/force.parquet"
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(
        DatasetError, match=r"force\.parquet: could not be read as Parquet"
    ):
        load_dataset(saved, verify=False)


def test_newer_schema_version_is_refused(saved: Path) -> None:
    """A dataset written by a newer schema asks for an upgrade instead of misreading it."""
    _edit_manifest(saved, schema_version=SCHEMA_VERSION + 1)
    with pytest.raises(
        DatasetError, match=r"manifest\.json: field 'schema_version' is 2, newer"
    ):
        load_dataset(saved)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"format": "something-else"}, "field 'format'"),
        ({"streams": []}, "streams: expected an object, got a list"),
        ({"schema_version": "1"}, 'schema_version: expected the integer 1, got "1"'),
    ],
)
def test_malformed_manifest_fields_are_named(
    saved: Path, change: dict, message: str
) -> None:
    """Wrong manifest fields are refused with the field's name and the expected type."""
    _edit_manifest(saved, **change)
    with pytest.raises(DatasetError, match=message):
        load_dataset(saved)


def test_missing_manifest_field_is_named(saved: Path) -> None:
    """A manifest without 'files' says which field is missing."""
    manifest = json.loads((saved / "manifest.json").read_text())
    del manifest["files"]
    (saved / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="missing field 'files'"):
        load_dataset(saved)


def test_not_a_dataset_folder(tmp_path: Path) -> None:
    """A folder without manifest.json is not taken for a dataset."""
    with pytest.raises(DatasetError, match=r"manifest\.json: missing"):
        load_dataset(tmp_path)


def test_missing_column_is_named(saved: Path) -> None:
    """A stream table without a declared channel names the file and the column."""
    df = pd.read_parquet(saved / "streams/force.parquet").drop(columns="fy")
    _rewrite(saved, "streams/force.parquet", df)
    with pytest.raises(DatasetError, match=r"force\.parquet: missing columns \['fy'\]"):
        load_dataset(saved)


def test_extra_column_is_named(saved: Path) -> None:
    """An undeclared column is refused, naming it."""
    df = pd.read_parquet(saved / "streams/force.parquet").assign(torque=0.0)
    _rewrite(saved, "streams/force.parquet", df)
    with pytest.raises(DatasetError, match=r"unexpected columns \['torque'\]"):
        load_dataset(saved)


def test_wrong_dtype_is_named(saved: Path) -> None:
    """A text column where a channel should be numeric names the column and dtype expected."""
    df = pd.read_parquet(saved / "streams/force.parquet")
    df["fx"] = df["fx"].astype(str)
    _rewrite(saved, "streams/force.parquet", df)
    with pytest.raises(
        DatasetError, match=r"column 'fx' has dtype .*expected a numeric dtype"
    ):
        load_dataset(saved)


def test_time_going_backwards_is_named(saved: Path) -> None:
    """Time that decreases inside a trial is refused with the row and trial."""
    df = pd.read_parquet(saved / "streams/force.parquet")
    df.loc[5, "t"] = -1.0
    _rewrite(saved, "streams/force.parquet", df)
    with pytest.raises(
        DatasetError, match=r"column 't' decreases at row 5 \(trial 'trial-000'\)"
    ):
        load_dataset(saved)


def test_unknown_trial_in_stream_is_named(saved: Path) -> None:
    """Rows whose trial is not in trials.parquet are refused."""
    df = pd.read_parquet(saved / "streams/force.parquet")
    df.loc[df["trial_id"] == "trial-005", "trial_id"] = "ghost"
    _rewrite(saved, "streams/force.parquet", df)
    with pytest.raises(DatasetError, match=r"not in trials\.parquet: \['ghost'\]"):
        load_dataset(saved)


def test_stray_stream_file_is_refused(saved: Path) -> None:
    """A Parquet file that the manifest does not list is reported, not silently ignored."""
    shutil.copy(saved / "streams/force.parquet", saved / "streams/force2.parquet")
    with pytest.raises(DatasetError, match=r"force2\.parquet: is not listed"):
        load_dataset(saved)


def test_class_outside_declared_classes_is_refused() -> None:
    """A class label value not among the declared class names is named."""
    trial = Trial(
        "a",
        {"force": pd.DataFrame({"t": [0.0], "fx": 0.0, "fy": 0.0, "fz": 0.0})},
        labels={"slip_onset_s": 0.0, "slip_class": "diagonal"},
    )
    with pytest.raises(DatasetError, match=r"column 'slip_class' holds \['diagonal'\]"):
        Dataset.from_trials(
            [trial], sensor="x", streams={"force": FORCE}, labels=LABELS
        )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"rate_hz": None}, "a sampled stream needs a rate"),
        ({"rate_hz": -1.0}, "a sampled stream needs a rate"),
        ({"units": {"a": "N"}}, r"no unit for channels \['b'\]"),
        ({"channels": ("a", "t"), "units": {"a": "N", "t": "s"}}, "reserved"),
        ({"kind": "events"}, "must be null for a events stream"),
    ],
)
def test_stream_spec_checks_its_fields(kwargs: dict, message: str) -> None:
    """StreamSpec refuses a missing rate, missing units, reserved names and kind/rate mismatches."""
    base = {
        "name": "s",
        "channels": ("a", "b"),
        "units": {"a": "N", "b": "N"},
        "rate_hz": 100.0,
    }
    with pytest.raises(DatasetError, match=message):
        StreamSpec(**{**base, **kwargs})


def test_duplicate_trial_ids_are_refused() -> None:
    """Two trials with one id cannot make a dataset."""
    frame = pd.DataFrame({"t": [0.0], "fx": 0.0, "fy": 0.0, "fz": 0.0})
    trials = [
        Trial(
            "same",
            {"force": frame},
            labels={"slip_onset_s": 0.0, "slip_class": "linear"},
        )
    ] * 2
    with pytest.raises(DatasetError, match="repeats 'same'"):
        Dataset.from_trials(trials, sensor="x", streams={"force": FORCE}, labels=LABELS)


# -- atomic writes -----------------------------------------------------------------------


def test_existing_folder_is_not_overwritten_by_default(saved: Path) -> None:
    """save_dataset refuses to replace a folder unless overwrite is asked for."""
    with pytest.raises(SlipkitError, match="already exists"):
        save_dataset(make_dataset(), saved)
    save_dataset(make_dataset(seed=9), saved, overwrite=True)
    assert make_dataset(seed=9).fingerprint() == load_dataset(saved).fingerprint()


def test_crash_mid_write_leaves_no_dataset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A failure while writing leaves neither the target folder nor a temporary folder."""
    calls = {"n": 0}
    real = dio._write_parquet

    def failing(df: pd.DataFrame, path: Path) -> None:
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError("disk full")
        real(df, path)

    monkeypatch.setattr(dio, "_write_parquet", failing)
    with pytest.raises(OSError, match="disk full"):
        save_dataset(make_dataset(), tmp_path / "ds")
    assert [] == os.listdir(tmp_path)


def test_crash_mid_overwrite_keeps_the_old_dataset(
    saved: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A failed overwrite leaves the previous complete dataset in place."""
    before = load_dataset(saved).fingerprint()

    def failing(df: pd.DataFrame, path: Path) -> None:
        raise OSError("killed")

    monkeypatch.setattr(dio, "_write_parquet", failing)
    with pytest.raises(OSError, match="killed"):
        save_dataset(make_dataset(seed=5), saved, overwrite=True)
    assert before == load_dataset(saved).fingerprint()
    assert ["ds"] == os.listdir(saved.parent)


def test_empty_event_stream_round_trips(tmp_path: Path) -> None:
    """A trial with no events still saves and loads (zero-row event stream)."""
    frame = pd.DataFrame({"t": np.arange(3) / 300.0, "fx": 0.0, "fy": 0.0, "fz": 0.0})
    events = pd.DataFrame(
        {
            "t": np.array([], float),
            "x": np.array([], np.int64),
            "y": np.array([], np.int64),
            "polarity": np.array([], np.int8),
        }
    )
    trial = Trial(
        "a",
        {"force": frame, "events": events},
        labels={"slip_onset_s": 0.1, "slip_class": "linear"},
    )
    from tests.strategies import EVENTS

    ds = Dataset.from_trials(
        [trial], sensor="x", streams={"force": FORCE, "events": EVENTS}, labels=LABELS
    )
    loaded = load_dataset(save_dataset(ds, tmp_path / "ds"))
    assert 0 == len(loaded.stream("events"))
    assert {"force"} == set(next(iter(loaded)).streams) - {"events"}


def test_label_spec_round_trips_through_json() -> None:
    """LabelSpec survives to_json/from_json, filling in standard descriptions."""
    spec = LabelSpec("slip_onset_s", unit="s")
    again = LabelSpec.from_json("slip_onset_s", spec.to_json())
    assert spec.unit == again.unit
    assert again.description.startswith("true slip onset")
