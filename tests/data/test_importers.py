"""Importers of real recordings: tiny files in each source's layout, malformed input,
the real data (when present), and ``slipkit import`` / ``slipkit info`` end to end."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest

from slipkit.cli import main
from slipkit.data import load_dataset
from slipkit.data.importers import (
    read_biotacsp_dos,
    read_bts3v2,
    read_csv_dataset,
    read_robotic_finger,
)
from slipkit.data.importers.biotacsp_dos import CHANNELS as DOS_CHANNELS
from slipkit.data.importers.biotacsp_dos import CLASSES as DOS_CLASSES
from slipkit.data.importers.bts3v2 import CHANNELS as BTS_CHANNELS
from slipkit.errors import SourceFormatError

# -- builders of tiny sources -------------------------------------------------------

DOS_OBJECTS = ("bottle", "pen")


def write_csv(path: Path, header: list[str], rows: Sequence[Sequence[object]]) -> Path:
    """Write a CSV with a header line; rows may be ragged on purpose."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [",".join(header), *(",".join(str(v) for v in row) for row in rows)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def make_dos(root: Path, n_rows: int = 5, per_object: int = 2) -> Path:
    """A mini BioTacSP-DoS folder: csvs/<class>/<object><n>.csv for 7 classes."""
    number = 0
    for k, cls in enumerate(DOS_CLASSES):
        for obj in DOS_OBJECTS:
            for _ in range(per_object):
                rows = [
                    [3000 + 100 * k + 10 * r + e for e in range(24)]
                    for r in range(n_rows)
                ]
                write_csv(
                    root / "csvs" / cls / f"{obj}{number}.csv", [*DOS_CHANNELS], rows
                )
                number += 1
    return root


BTS_HEADER = ["object", "slipped", *BTS_CHANNELS]


def bts_rows(objects: list[str], slipped: list[int]) -> list[list[object]]:
    """Grasp rows: object, slipped, 72 electrode values."""
    return [
        [obj, s, *(2000 + 10 * i + e for e in range(72))]
        for i, (obj, s) in enumerate(zip(objects, slipped, strict=True))
    ]


def make_bts3v2(root: Path) -> Path:
    """A mini bts3v2 folder: three orientation files, 2 + 3 + 1 grasps."""
    write_csv(
        root / "bts3v2_palm_down.csv", BTS_HEADER, bts_rows(["mug", "ball"], [0, 1])
    )
    write_csv(
        root / "bts3v2_palm_side.csv",
        BTS_HEADER,
        bts_rows(["mug", "can", "can"], [1, 1, 0]),
    )
    write_csv(root / "bts3v2_palm_45.csv", BTS_HEADER, bts_rows(["ball"], [0]))
    return root


def write_matrix(path: Path, rows: np.ndarray | list[list[float]]) -> Path:
    """Whitespace-separated matrix, one line per row, as in X1.txt / Y1.txt."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["   ".join(f"{v: .7e}" for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def finger_arrays(n: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """(X 19 x n electrodes, Y 3 x n unit directions)."""
    x = np.arange(19 * n, dtype=float).reshape(19, n) - 40.0
    raw = np.stack([np.ones(n), np.arange(n, dtype=float), -np.ones(n)])
    return x, raw / np.linalg.norm(raw, axis=0)


def make_finger(root: Path, n: int = 5) -> Path:
    """A mini Robotic-Finger folder: X1.txt (19 x n) and Y1.txt (3 x n)."""
    x, y = finger_arrays(n)
    write_matrix(root / "X1.txt", x)
    write_matrix(root / "Y1.txt", y)
    return root


def make_csv_folder(root: Path) -> Path:
    """Three generic CSV trials with two channels, a label and a group column."""
    for name, obj, onset in (
        ("a", "cube", 0.5),
        ("b", "cube", np.nan),
        ("c", "ball", 1.0),
    ):
        rows = [[obj, onset, 0.1 * r, 2.0 * r] for r in range(4)]
        write_csv(root / f"{name}.csv", ["object", "slip_onset_s", "fx", "fz"], rows)
    return root


# -- BioTacSP-DoS ---------------------------------------------------------------------


def test_dos_trials_labels_groups(tmp_path: Path) -> None:
    """Each DoS file becomes a trial with its class, slip type, object and 24 channels."""
    ds = read_biotacsp_dos(make_dos(tmp_path / "dos"))
    assert 7 * 2 * 2 == len(ds)
    assert "biotac_sp" == ds.sensor
    assert DOS_CLASSES == ds.class_names("slip_class")
    assert ("linear", "rotational", "touch") == ds.class_names("slip_type")
    assert {c: 4 for c in DOS_CLASSES} == ds.trials[
        "slip_class"
    ].value_counts().to_dict()
    assert {"linear": 16, "rotational": 8, "touch": 4} == (
        ds.trials["slip_type"].value_counts().to_dict()
    )
    assert ("object",) == ds.groups
    assert {"bottle": 14, "pen": 14} == ds.trials["object"].value_counts().to_dict()
    assert "n/bottle0" == ds.trial_ids[0]
    assert 0 == int(ds.trials["slip_onset_s"].notna().sum())
    spec = ds.streams["electrodes"]
    assert (DOS_CHANNELS, 100.0, "sampled") == (spec.channels, spec.rate_hz, spec.kind)
    assert {"ADC"} == set(spec.units.values())
    assert 28 * 5 == len(ds.stream("electrodes"))


def test_dos_time_and_values(tmp_path: Path) -> None:
    """Times are row / rate_hz and electrode values are copied from the file."""
    ds = read_biotacsp_dos(make_dos(tmp_path / "dos"), rate_hz=50.0)
    trial = ds["e/pen6"]
    frame = trial.streams["electrodes"]
    np.testing.assert_allclose([0.0, 0.02, 0.04, 0.06, 0.08], frame["t"].to_numpy())
    assert [3100.0, 3110.0] == frame["ff_e1"].iloc[:2].tolist()
    assert 3123.0 == frame["ff_e24"].iloc[0]
    assert ("e", "linear", "pen") == (
        trial.labels["slip_class"],
        trial.labels["slip_type"],
        trial.meta["object"],
    )
    assert 50.0 == ds.provenance["rate_hz"]


def test_dos_accepts_the_csvs_folder(tmp_path: Path) -> None:
    """The csvs/ folder itself reads the same as its parent."""
    root = make_dos(tmp_path / "dos")
    assert read_biotacsp_dos(root).fingerprint() == (
        read_biotacsp_dos(root / "csvs").fingerprint()
    )


def test_dos_wrong_header_names_file_and_column(tmp_path: Path) -> None:
    """A header that is not ff_e1..ff_e24 is rejected naming the file and column."""
    root = make_dos(tmp_path / "dos")
    bad = root / "csvs" / "s" / "pen9.csv"
    write_csv(bad, [*DOS_CHANNELS[:3], "ff_x4", *DOS_CHANNELS[4:]], [[1] * 24])
    with pytest.raises(
        SourceFormatError, match=r"pen9\.csv: header column 4 is 'ff_x4'"
    ):
        read_biotacsp_dos(root)


def test_dos_long_row_names_file_and_line(tmp_path: Path) -> None:
    """A row with more fields than the header is rejected naming the file and line."""
    root = make_dos(tmp_path / "dos")
    bad = root / "csvs" / "w" / "bottle12.csv"
    write_csv(bad, [*DOS_CHANNELS], [[1] * 24, [1] * 25])
    with pytest.raises(
        SourceFormatError, match=r"bottle12\.csv: malformed CSV.*line 3"
    ):
        read_biotacsp_dos(root)


def test_dos_short_row_names_file_line_and_column(tmp_path: Path) -> None:
    """A row with fewer fields than the header is rejected naming file, line, column."""
    root = make_dos(tmp_path / "dos")
    bad = root / "csvs" / "w" / "bottle12.csv"
    write_csv(bad, [*DOS_CHANNELS], [[1] * 24, [1] * 24, [1] * 22])
    with pytest.raises(
        SourceFormatError, match=r"bottle12\.csv: line 4, column 'ff_e23': missing"
    ):
        read_biotacsp_dos(root)


def test_dos_text_value_names_file_line_and_column(tmp_path: Path) -> None:
    """A value that is not a number is rejected naming the file, line and column."""
    root = make_dos(tmp_path / "dos")
    bad = root / "csvs" / "t" / "pen1.csv"
    write_csv(bad, [*DOS_CHANNELS], [[1] * 24, [1] * 5 + ["x"] + [1] * 18])
    with pytest.raises(
        SourceFormatError,
        match=r"pen1\.csv: line 3, column 'ff_e6': 'x' is not a number",
    ):
        read_biotacsp_dos(root)


def test_dos_unknown_class_folder(tmp_path: Path) -> None:
    """A folder of CSVs whose name is not a class is rejected naming the folder."""
    root = make_dos(tmp_path / "dos")
    write_csv(root / "csvs" / "up" / "pen1.csv", [*DOS_CHANNELS], [[1] * 24])
    with pytest.raises(SourceFormatError, match=r"up: folder name 'up' is not"):
        read_biotacsp_dos(root)


def test_dos_empty_folder(tmp_path: Path) -> None:
    """A folder without class folders of CSVs is rejected, saying what was expected."""
    (tmp_path / "empty").mkdir()
    with pytest.raises(SourceFormatError, match=r"no CSV files in class folders"):
        read_biotacsp_dos(tmp_path / "empty")


# -- bts3v2 -------------------------------------------------------------------------


def test_bts3v2_one_snapshot_trial_per_grasp(tmp_path: Path) -> None:
    """Each grasp row becomes a snapshot trial with object, orientation and outcome."""
    ds = read_bts3v2(make_bts3v2(tmp_path / "bts"))
    assert 6 == len(ds)
    assert "biotac_sp_x3" == ds.sensor
    assert ("object", "orientation") == ds.groups
    assert ("stable", "slipped") == ds.class_names("slip_class")
    assert {"stable": 3, "slipped": 3} == ds.trials[
        "slip_class"
    ].value_counts().to_dict()
    assert {"palm_down": 2, "palm_side": 3, "palm_45": 1} == (
        ds.trials["orientation"].value_counts(sort=False).to_dict()
    )
    assert {"mug": 2, "ball": 2, "can": 2} == ds.trials[
        "object"
    ].value_counts().to_dict()
    spec = ds.streams["electrodes"]
    assert (72, None, "snapshot") == (len(spec.channels), spec.rate_hz, spec.kind)
    assert ("ff_biotac_1", "mf_biotac_1", "th_biotac_24") == (
        spec.channels[0],
        spec.channels[24],
        spec.channels[71],
    )
    table = ds.stream("electrodes")
    assert 6 == len(table)
    assert {0.0} == set(table["t"])
    trial = ds["palm_side/0001"]
    assert ("can", "slipped") == (trial.meta["object"], trial.labels["slip_class"])
    assert 2010.0 == trial.streams["electrodes"]["ff_biotac_1"].iloc[0]


def test_bts3v2_single_file(tmp_path: Path) -> None:
    """One orientation file alone reads into that file's grasps."""
    ds = read_bts3v2(make_bts3v2(tmp_path / "bts") / "bts3v2_palm_side.csv")
    assert ["palm_side/0000", "palm_side/0001", "palm_side/0002"] == ds.trial_ids


def test_bts3v2_wrong_header_names_file(tmp_path: Path) -> None:
    """A header without the 'slipped' column is rejected naming the file and column."""
    root = make_bts3v2(tmp_path / "bts")
    header = ["object", "slip", *BTS_CHANNELS]
    write_csv(root / "bts3v2_palm_45.csv", header, bts_rows(["mug"], [0]))
    with pytest.raises(
        SourceFormatError, match=r"bts3v2_palm_45\.csv: header column 2 is 'slip'"
    ):
        read_bts3v2(root)


def test_bts3v2_bad_outcome_names_file_line(tmp_path: Path) -> None:
    """A 'slipped' value other than 0 or 1 is rejected naming the file and line."""
    root = make_bts3v2(tmp_path / "bts")
    write_csv(root / "bts3v2_palm_45.csv", BTS_HEADER, bts_rows(["a", "b"], [0, 2]))
    with pytest.raises(
        SourceFormatError, match=r"bts3v2_palm_45\.csv: line 3, column 'slipped'"
    ):
        read_bts3v2(root)


def test_bts3v2_ragged_row_names_file(tmp_path: Path) -> None:
    """A grasp row with a missing electrode value is rejected naming the file."""
    root = make_bts3v2(tmp_path / "bts")
    rows = bts_rows(["a", "b"], [0, 1])
    rows[1] = rows[1][:-1]
    write_csv(root / "bts3v2_palm_down.csv", BTS_HEADER, rows)
    with pytest.raises(
        SourceFormatError,
        match=r"bts3v2_palm_down\.csv: line 3, column 'th_biotac_24': missing",
    ):
        read_bts3v2(root)


def test_bts3v2_published_test_files_beside_the_training_files(tmp_path: Path) -> None:
    """The published ``_test`` files read with the training files, each grasp marked
    with its set; ids stay unique and the training ids unchanged."""
    root = make_bts3v2(tmp_path / "bts")
    write_csv(
        root / "bts3v2_palm_down_test.csv", BTS_HEADER, bts_rows(["cup", "box"], [1, 0])
    )
    write_csv(root / "bts3v2_palm_45_test.csv", BTS_HEADER, bts_rows(["cup"], [1]))
    ds = read_bts3v2(root)
    assert 9 == len(ds)
    assert ["palm_down/0000", "palm_down/0001"] == ds.trial_ids[:2]
    assert ["palm_down_test/0000", "palm_down_test/0001", "palm_45_test/0000"] == (
        ds.trial_ids[6:]
    )
    sets = ds.trials.set_index("trial_id")["published_split"]
    assert ["train"] * 6 + ["test"] * 3 == sets.tolist()
    assert "palm_45" == ds["palm_45_test/0000"].meta["orientation"]
    alone = read_bts3v2(root / "bts3v2_palm_down_test.csv")
    assert {"test"} == set(alone.trials["published_split"])


def test_bts3v2_two_files_of_one_orientation_and_set(tmp_path: Path) -> None:
    """Two files of one orientation in the same set are refused, naming both."""
    root = make_bts3v2(tmp_path / "bts")
    write_csv(root / "old_palm_45.csv", BTS_HEADER, bts_rows(["a"], [0]))
    with pytest.raises(SourceFormatError, match=r"palm_45\.csv: orientation 'palm_45'"):
        read_bts3v2(root)


def test_bts3v2_file_without_orientation(tmp_path: Path) -> None:
    """A CSV whose name carries no orientation is rejected naming the file."""
    root = make_bts3v2(tmp_path / "bts")
    write_csv(root / "grasps.csv", BTS_HEADER, bts_rows(["a"], [0]))
    with pytest.raises(SourceFormatError, match=r"grasps\.csv: file name does not end"):
        read_bts3v2(root)


# -- Robotic-Finger -----------------------------------------------------------------


def test_finger_one_trial_per_sample(tmp_path: Path) -> None:
    """Each column of X1/Y1 becomes a trial with 19 electrodes and a unit direction."""
    ds = read_robotic_finger(make_finger(tmp_path / "finger"))
    x, y = finger_arrays()
    assert 5 == len(ds)
    assert "biotac" == ds.sensor
    assert ["sample0000", "sample0001"] == ds.trial_ids[:2]
    electrodes = ds.stream("electrodes")
    direction = ds.stream("truth_force_dir")
    assert (19, 3) == (len(ds.streams["electrodes"].channels), 3)
    assert ("ux", "uy", "uz") == ds.streams["truth_force_dir"].channels
    assert {"ADC (mean-centred)"} == set(ds.streams["electrodes"].units.values())
    assert {"1"} == set(ds.streams["truth_force_dir"].units.values())
    assert "snapshot" == ds.streams["truth_force_dir"].kind
    np.testing.assert_allclose(x.T, electrodes.loc[:, "e1":"e19"].to_numpy())
    np.testing.assert_allclose(y.T, direction[["ux", "uy", "uz"]].to_numpy(), rtol=1e-6)
    assert {0.0} == set(electrodes["t"])
    assert {} == ds.labels


def test_finger_non_unit_direction_names_file_and_column(tmp_path: Path) -> None:
    """A direction of norm far from 1 is rejected naming Y1.txt and its column."""
    root = make_finger(tmp_path / "finger")
    _, y = finger_arrays()
    y[:, 3] *= 0.5
    write_matrix(root / "Y1.txt", y)
    with pytest.raises(
        SourceFormatError, match=r"Y1\.txt: column 4 \(sample 3\) has norm 0\.5"
    ):
        read_robotic_finger(root)


def test_finger_column_counts_disagree(tmp_path: Path) -> None:
    """X1 and Y1 with different sample counts are rejected naming both files."""
    root = make_finger(tmp_path / "finger")
    _, y = finger_arrays(4)
    write_matrix(root / "Y1.txt", y)
    with pytest.raises(
        SourceFormatError, match=r"Y1\.txt: has 4 columns.*X1\.txt has 5"
    ):
        read_robotic_finger(root)


def test_finger_ragged_rows_name_file_and_line(tmp_path: Path) -> None:
    """A row of X1 shorter than the others is rejected naming the file and line."""
    root = make_finger(tmp_path / "finger")
    x, _ = finger_arrays()
    rows = [list(r) for r in x]
    rows[6] = rows[6][:-1]
    write_matrix(root / "X1.txt", rows)
    with pytest.raises(SourceFormatError, match=r"X1\.txt: line 7 has 4 values"):
        read_robotic_finger(root)


def test_finger_wrong_row_count(tmp_path: Path) -> None:
    """An X1 with 18 electrode rows is rejected naming the file and the count."""
    root = make_finger(tmp_path / "finger")
    x, _ = finger_arrays()
    write_matrix(root / "X1.txt", x[:18])
    with pytest.raises(SourceFormatError, match=r"X1\.txt: has 18 rows; expected 19"):
        read_robotic_finger(root)


def test_finger_text_value_names_line_and_column(tmp_path: Path) -> None:
    """A token that is not a number is rejected naming the file, line and column."""
    root = make_finger(tmp_path / "finger")
    text = (root / "Y1.txt").read_text().splitlines()
    tokens = text[1].split()
    tokens[2] = "nope"
    text[1] = " ".join(tokens)
    (root / "Y1.txt").write_text("\n".join(text) + "\n")
    with pytest.raises(
        SourceFormatError, match=r"Y1\.txt: line 2, column 3: 'nope' is not a number"
    ):
        read_robotic_finger(root)


# -- generic CSV --------------------------------------------------------------------


def test_csv_folder_with_rate(tmp_path: Path) -> None:
    """Each CSV is a trial; channels default to the numeric non-label columns."""
    ds = read_csv_dataset(
        make_csv_folder(tmp_path / "rec"),
        sensor="fsr",
        rate_hz=10.0,
        units={"fx": "N", "fz": "N"},
        label_columns=["slip_onset_s"],
        group_columns=["object"],
    )
    assert ["a", "b", "c"] == ds.trial_ids
    assert "fsr" == ds.sensor
    spec = ds.streams["signal"]
    assert (("fx", "fz"), 10.0, {"N"}) == (
        spec.channels,
        spec.rate_hz,
        set(spec.units.values()),
    )
    assert "s" == ds.labels["slip_onset_s"].unit
    assert ("object",) == ds.groups
    assert {"cube": 2, "ball": 1} == ds.trials["object"].value_counts().to_dict()
    np.testing.assert_allclose([0.5, np.nan, 1.0], ds.trials["slip_onset_s"].to_numpy())
    frame = ds["c"].streams["signal"]
    np.testing.assert_allclose([0.0, 0.1, 0.2, 0.3], frame["t"].to_numpy())
    np.testing.assert_allclose([0.0, 2.0, 4.0, 6.0], frame["fz"].to_numpy())


def test_csv_time_column_infers_rate(tmp_path: Path) -> None:
    """Times come from the time column and the nominal rate from its median step."""
    rows = [[0.002 * r, float(r)] for r in range(6)]
    write_csv(tmp_path / "one.csv", ["time", "v"], rows)
    ds = read_csv_dataset(
        tmp_path / "one.csv", sensor="x", time_column="time", units="V"
    )
    assert 500.0 == ds.streams["signal"].rate_hz
    assert ("v",) == ds.streams["signal"].channels
    np.testing.assert_allclose(
        [r[0] for r in rows], ds.stream("signal")["t"].to_numpy()
    )
    assert ["one"] == ds.trial_ids


def test_csv_trial_column_splits_a_file(tmp_path: Path) -> None:
    """A trial column splits one file into trials, with class labels as declared."""
    rows = [
        [1, "slip", 0.1],
        [2, "hold", 0.2],
        [1, "slip", 0.3],
        [2, "hold", 0.4],
        [2, "hold", 0.5],
    ]
    write_csv(tmp_path / "runs.csv", ["run", "outcome", "p"], rows)
    ds = read_csv_dataset(
        tmp_path / "runs.csv",
        sensor="x",
        rate_hz=100.0,
        trial_column="run",
        label_columns=["outcome"],
        class_labels={"outcome": ["hold", "slip"]},
    )
    assert ["1", "2"] == ds.trial_ids
    assert ("hold", "slip") == ds.class_names("outcome")
    assert {"slip": 1, "hold": 1} == ds.trials["outcome"].value_counts().to_dict()
    frame = ds["2"].streams["signal"]
    np.testing.assert_allclose([0.2, 0.4, 0.5], frame["p"].to_numpy())
    np.testing.assert_allclose([0.0, 0.01, 0.02], frame["t"].to_numpy())


def test_csv_trial_ids_in_a_folder_carry_the_file(tmp_path: Path) -> None:
    """In a folder, trial ids split by the trial column are '<file>/<value>'."""
    for name in ("a", "b"):
        write_csv(tmp_path / "rec" / f"{name}.csv", ["run", "p"], [[7, 1.0], [8, 2.0]])
    ds = read_csv_dataset(tmp_path / "rec", sensor="x", trial_column="run")
    assert ["a/7", "a/8", "b/7", "b/8"] == ds.trial_ids
    assert "snapshot" == ds.streams["signal"].kind


def test_csv_label_varying_within_trial(tmp_path: Path) -> None:
    """A label that changes within a trial is rejected naming file, column and trial."""
    root = make_csv_folder(tmp_path / "rec")
    write_csv(
        root / "b.csv",
        ["object", "slip_onset_s", "fx", "fz"],
        [["cube", 0.5, 0, 0], ["cube", 0.7, 1, 1]],
    )
    with pytest.raises(
        SourceFormatError,
        match=r"b\.csv: column 'slip_onset_s' varies within trial 'b'.*line 3",
    ):
        read_csv_dataset(
            root,
            sensor="x",
            rate_hz=1.0,
            label_columns=["slip_onset_s"],
            group_columns=["object"],
        )


def test_csv_missing_column_names_file_and_column(tmp_path: Path) -> None:
    """A group column absent from a file is rejected naming the file and column."""
    root = make_csv_folder(tmp_path / "rec")
    write_csv(root / "c.csv", ["slip_onset_s", "fx", "fz"], [[0.1, 1, 2]])
    with pytest.raises(SourceFormatError, match=r"c\.csv: no column 'object'"):
        read_csv_dataset(
            root,
            sensor="x",
            rate_hz=1.0,
            label_columns=["slip_onset_s"],
            group_columns=["object"],
        )


def test_csv_missing_value_in_channel(tmp_path: Path) -> None:
    """An empty channel field is rejected naming the file, line and column."""
    root = make_csv_folder(tmp_path / "rec")
    with pytest.raises(
        SourceFormatError, match=r"b\.csv: line 2, column 'slip_onset_s': missing"
    ):
        read_csv_dataset(root, sensor="x", rate_hz=1.0, group_columns=["object"])


def test_csv_text_channel_names_file_and_column(tmp_path: Path) -> None:
    """A text value in a declared channel is rejected naming file, line and column."""
    write_csv(tmp_path / "r.csv", ["fx", "fz"], [[1, 2], [3, "high"]])
    with pytest.raises(
        SourceFormatError, match=r"r\.csv: line 3, column 'fz': 'high' is not a number"
    ):
        read_csv_dataset(
            tmp_path / "r.csv", sensor="x", rate_hz=1.0, channels=["fx", "fz"]
        )


def test_csv_channels_differ_between_files(tmp_path: Path) -> None:
    """Files whose channel columns differ are rejected naming the later file."""
    root = make_csv_folder(tmp_path / "rec")
    write_csv(root / "c.csv", ["object", "slip_onset_s", "fx"], [["ball", 0.1, 1]])
    with pytest.raises(SourceFormatError, match=r"c\.csv: channel columns fx differ"):
        read_csv_dataset(
            root,
            sensor="x",
            rate_hz=1.0,
            label_columns=["slip_onset_s"],
            group_columns=["object"],
        )


def test_csv_class_value_outside_classes(tmp_path: Path) -> None:
    """A class label value outside class_labels is rejected naming file and column."""
    write_csv(tmp_path / "r.csv", ["kind", "p"], [["slip", 1.0], ["slip", 2.0]])
    with pytest.raises(
        SourceFormatError, match=r"r\.csv: line 2, column 'kind': value 'slip'"
    ):
        read_csv_dataset(
            tmp_path / "r.csv",
            sensor="x",
            rate_hz=1.0,
            label_columns=["kind"],
            class_labels={"kind": ["stable"]},
        )


def test_csv_time_going_backwards(tmp_path: Path) -> None:
    """A time column that decreases within a trial is rejected naming file and line."""
    write_csv(tmp_path / "r.csv", ["t_s", "p"], [[0.0, 1], [0.2, 2], [0.1, 3]])
    with pytest.raises(
        SourceFormatError, match=r"r\.csv: line 4, column 't_s': time decreases"
    ):
        read_csv_dataset(tmp_path / "r.csv", sensor="x", time_column="t_s")


def test_csv_ragged_row_names_file(tmp_path: Path) -> None:
    """A row with an extra field is rejected naming the file and line."""
    write_csv(tmp_path / "r.csv", ["fx", "fz"], [[1, 2], [3, 4, 5]])
    with pytest.raises(SourceFormatError, match=r"r\.csv: malformed CSV.*line 3"):
        read_csv_dataset(tmp_path / "r.csv", sensor="x", rate_hz=1.0)


def test_csv_units_mapping_must_cover_channels(tmp_path: Path) -> None:
    """A units mapping without a channel's unit is rejected naming the channel."""
    with pytest.raises(
        SourceFormatError, match=r"units: no unit for channels \['fz'\]"
    ):
        read_csv_dataset(
            make_csv_folder(tmp_path / "rec"),
            sensor="x",
            rate_hz=1.0,
            units={"fx": "N"},
            label_columns=["slip_onset_s"],
            group_columns=["object"],
        )


def test_csv_snapshot_needs_one_row_per_trial(tmp_path: Path) -> None:
    """Without time column or rate, a multi-row trial is rejected naming file and trial."""
    write_csv(tmp_path / "r.csv", ["p"], [[1], [2]])
    with pytest.raises(SourceFormatError, match=r"r\.csv: trial 'r' has 2 rows"):
        read_csv_dataset(tmp_path / "r.csv", sensor="x")


# -- the real recordings ------------------------------------------------------------


@pytest.mark.realdata
def test_real_biotacsp_dos(shared_data: Path) -> None:
    """The real DoS folder gives 223 sequences of 24 channels over 7 classes, 8 objects."""
    ds = read_biotacsp_dos(shared_data / "biotacsp-dos")
    # The copy holds 223 files, not 7 x 8 x 4 = 224: aw has 3 brush and 5 screw
    # sequences, w has 3 pen sequences.
    assert 223 == len(ds)
    assert 24 == len(ds.streams["electrodes"].channels)
    assert {"n": 32, "e": 32, "s": 32, "w": 31, "cw": 32, "aw": 32, "t": 32} == (
        ds.trials["slip_class"].value_counts().to_dict()
    )
    assert {"bottle", "brush", "cardboard", "case", "hd", "pen", "screw", "sponge"} == (
        set(ds.trials["object"])
    )
    lengths = ds.stream("electrodes").groupby("trial_id").size()
    assert (270, 281) == (int(lengths.min()), int(lengths.max()))


@pytest.mark.realdata
def test_real_bts3v2(shared_data: Path) -> None:
    """The real bts3v2 files give 4682 grasps of 72 channels over 41 objects."""
    ds = read_bts3v2(shared_data / "bts3v2")
    assert 4682 == len(ds)
    assert 72 == len(ds.streams["electrodes"].channels)
    assert 41 == ds.trials["object"].nunique()
    assert {"palm_down": 1276, "palm_side": 1273, "palm_45": 2133} == (
        ds.trials["orientation"].value_counts(sort=False).to_dict()
    )
    assert 4682 == int(ds.trials["slip_class"].isin(["stable", "slipped"]).sum())


@pytest.mark.realdata
def test_real_robotic_finger(shared_data: Path) -> None:
    """The real Robotic-Finger files give 4030 samples of 19 electrodes + 3 directions."""
    ds = read_robotic_finger(shared_data / "robotic-finger")
    assert 4030 == len(ds)
    assert (19, 3) == (
        len(ds.streams["electrodes"].channels),
        len(ds.streams["truth_force_dir"].channels),
    )
    direction = ds.stream("truth_force_dir")[["ux", "uy", "uz"]].to_numpy()
    np.testing.assert_allclose(
        np.ones(4030), np.linalg.norm(direction, axis=1), atol=1e-6
    )


# -- end to end through the CLI ------------------------------------------------------


def summary_lines(text: str, start: str) -> list[str]:
    """Lines of a printed summary that begin with ``start``."""
    return [line for line in text.splitlines() if line.startswith(start)]


def run_import_and_info(
    capsys: pytest.CaptureFixture[str], args: list[str], out: Path
) -> tuple[str, str]:
    """Run `slipkit import ... out=<out>` then `slipkit info`; return both outputs."""
    main(["import", *args, f"out={out}"])
    imported = capsys.readouterr().out
    main(["info", f"dataset={out}"])
    return imported, capsys.readouterr().out


@pytest.mark.parametrize(
    ("source", "make", "extra", "n_trials"),
    [
        ("biotacsp_dos", make_dos, [], 28),
        ("bts3v2", make_bts3v2, [], 6),
        ("robotic_finger", make_finger, [], 5),
        (
            "csv",
            make_csv_folder,
            [
                "source.sensor=fsr",
                "source.rate_hz=10",
                "source.units=N",
                "source.label_columns=[slip_onset_s]",
                "source.group_columns=[object]",
            ],
            3,
        ),
    ],
)
def test_cli_import_then_info(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    source: str,
    make: Callable[[Path], Path],
    extra: list[str],
    n_trials: int,
) -> None:
    """`slipkit import` prints the dataset path last and `slipkit info` summarises it."""
    src = make(tmp_path / "src")
    out = tmp_path / "ds"
    imported, info = run_import_and_info(
        capsys, [f"source={source}", f"path={src}", *extra], out
    )
    assert str(out) == imported.strip().splitlines()[-1]
    assert [f"trials    {n_trials}"] == summary_lines(info, "trials")
    assert n_trials == len(load_dataset(out))


@pytest.mark.realdata
def test_cli_real_biotacsp_dos(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Importing the real DoS folder with the CLI writes a dataset that loads unchanged."""
    out = tmp_path / "dos"
    src = shared_data / "biotacsp-dos"
    imported, info = run_import_and_info(
        capsys, ["source=biotacsp_dos", f"path={src}"], out
    )
    assert str(out) == imported.strip().splitlines()[-1]
    assert [
        "  slip_class         n: 32, e: 32, s: 32, w: 31, cw: 32, aw: 32, t: 32"
    ] == summary_lines(info, "  slip_class")
    loaded = load_dataset(out)
    assert read_biotacsp_dos(src).fingerprint() == loaded.fingerprint()
    assert 0 == int(loaded.trials["slip_onset_s"].notna().sum())
