"""The CSV importer's text options (delimiter, decimal, encoding) and its early refusals.

A European lab export (``;`` between fields, decimal commas, a latin-1 header) reads
with ``delimiter=';'``, ``decimal=','``, ``encoding='latin-1'``; read with the
defaults, its field-count error says which delimiter fits. A first data row with
millions of fields is refused from its first MiB, before pandas reads it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from slipkit.data.dataset import Dataset, StreamSpec
from slipkit.data.importers import read_csv_dataset
from slipkit.errors import DatasetError, SourceFormatError

EUROPEAN = "zeit;kraft_µN;schlupf\n0,0;1,5;0\n0,1;2,5;0\n0,2;-3,25;1\n"


@pytest.fixture
def european(tmp_path: Path) -> Path:
    path = tmp_path / "eu.csv"
    path.write_bytes(EUROPEAN.encode("latin-1"))
    return path


def test_a_european_export_reads_with_its_three_options(european: Path) -> None:
    """';' fields, decimal commas and a latin-1 header read as numbers under their own names."""
    ds = read_csv_dataset(
        european,
        sensor="generic",
        time_column="zeit",
        delimiter=";",
        decimal=",",
        encoding="latin-1",
    )
    table = ds.tables["signal"]
    assert (("kraft_µN", "schlupf"), [1.5, 2.5, -3.25], [0.0, 0.1, 0.2]) == (
        ds.streams["signal"].channels,
        table["kraft_µN"].tolist(),
        table["t"].tolist(),
    )


def test_the_wrong_delimiter_is_named_with_the_one_that_fits(european: Path) -> None:
    """Read with ',' the export's line 2 is refused with the hint to set source.delimiter=';'."""
    with pytest.raises(SourceFormatError) as refused:
        read_csv_dataset(european, sensor="generic", encoding="latin-1")
    assert (
        f"{european}: line 2 has 3 fields but the header (line 1) has 1; every row "
        "needs as many fields as the header; is the delimiter ';'? set "
        "\"source.delimiter=';'\""
    ) == str(refused.value)


def test_the_wrong_encoding_is_named(european: Path) -> None:
    """A latin-1 file read as UTF-8 is one error naming the encoding option."""
    with pytest.raises(
        SourceFormatError, match=r"is not utf-8 text .*source\.encoding"
    ):
        read_csv_dataset(european, sensor="generic", delimiter=";")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"delimiter": ";;"}, "delimiter=';;': expected one character"),
        ({"decimal": ""}, "decimal='': expected one character"),
        (
            {"delimiter": ";", "decimal": ";"},
            "decimal=';': the same character as delimiter",
        ),
        ({"encoding": "klingon"}, "encoding='klingon': unknown text encoding"),
    ],
)
def test_bad_text_options_are_refused(
    european: Path, options: dict[str, str], message: str
) -> None:
    """A delimiter or decimal mark that is not one character, or an unknown encoding, is named."""
    with pytest.raises(SourceFormatError, match=message):
        read_csv_dataset(european, sensor="generic", **options)  # type: ignore[arg-type]


def test_a_tab_is_given_by_name(tmp_path: Path) -> None:
    """delimiter='tab' (or '\\t' as typed on a command line) reads tab-separated fields."""
    path = tmp_path / "tabs.csv"
    path.write_text("t\ta\n0\t1\n1\t2\n", encoding="utf-8")
    ds = read_csv_dataset(path, sensor="generic", time_column="t", delimiter="tab")
    assert [1.0, 2.0] == ds.tables["signal"]["a"].tolist()


def test_a_first_row_of_millions_of_fields_is_refused_early(tmp_path: Path) -> None:
    """A second line of 1.8 million fields is refused from its first MiB, naming the line."""
    path = tmp_path / "wide.csv"
    path.write_text(
        "t,a\n" + ",".join(["1"] * 1_800_000) + "\n0.1,2\n", encoding="utf-8"
    )
    with pytest.raises(SourceFormatError) as refused:
        read_csv_dataset(path, sensor="generic", time_column="t")
    assert (
        f"{path}: line 2 has at least 524289 fields but the header (line 1) has 2; "
        "every row needs as many fields as the header"
    ) == str(refused.value)


def test_a_true_false_channel_in_a_dataset_is_refused() -> None:
    """A dataset channel of True/False values is a DatasetError naming the column, not 1/0."""
    table = pd.DataFrame(
        {"trial_id": ["a", "a"], "t": [0.0, 0.1], "touch": np.array([True, False])}
    )
    with pytest.raises(DatasetError) as refused:
        Dataset(
            sensor="generic",
            streams={"s": StreamSpec("s", ("touch",), {"touch": "1"}, rate_hz=10.0)},
            trials=pd.DataFrame({"trial_id": ["a"]}),
            tables={"s": table},
        )
    assert (
        "stream 's': column 'touch' holds true/false values (dtype bool); expected "
        "numbers (write 1/0 if it is a measured on/off signal)"
    ) == str(refused.value)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            {"label_columns": "slip"},
            "label_columns='slip': expected a list of column names",
        ),
        (
            {"group_columns": None},
            "group_columns=null: expected a list of column names",
        ),
        ({"channels": "a"}, "channels='a': expected a list of column names"),
        (
            {"trial_column": ["a"]},
            r"trial_column=\['a'\]: expected a column name or null",
        ),
        ({"class_labels": "abc"}, "class_labels='abc': expected a mapping"),
        ({"units": 5}, "units=5: expected one unit such as N"),
        ({"sensor": None}, "sensor=null: expected a non-empty name"),
        ({"glob": ""}, "glob='': expected a non-empty file pattern"),
    ],
)
def test_an_argument_of_the_wrong_kind_is_named(
    tmp_path: Path, options: dict[str, object], message: str
) -> None:
    """A text where a list belongs (read letter by letter before) or a null list is refused, naming it."""
    path = tmp_path / "x.csv"
    path.write_text("t,a,slip\n0,1,0\n0.1,2,0\n", encoding="utf-8")
    kwargs: dict[str, object] = {"sensor": "generic", "time_column": "t", **options}
    with pytest.raises(SourceFormatError, match=message):
        read_csv_dataset(path, **kwargs)  # type: ignore[arg-type]
