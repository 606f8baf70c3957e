"""Generic CSV importer, and the checked CSV reading the source importers share.

:func:`read_csv_dataset` turns a CSV file, or a folder of them, into a
:class:`~slipkit.data.dataset.Dataset` with one stream: each file is a trial, or
a ``trial_column`` splits a file into trials. The helpers :func:`read_csv_file`,
:func:`check_header` and :func:`numeric_block` turn pandas' parse failures into
:class:`~slipkit.errors.SourceFormatError` messages that name the file, the line
(1-based, the header is line 1) and the column.
"""

from __future__ import annotations

import codecs
import csv
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import STANDARD_LABELS, Dataset, LabelSpec, StreamSpec
from slipkit.errors import SourceFormatError
from slipkit.evaluate.events import SLIPPED_LABEL

__all__ = [
    "check_header",
    "line_of",
    "numeric_block",
    "read_csv_dataset",
    "read_csv_file",
]

#: Unit given to channels when ``units`` is None.
UNKNOWN_UNIT = "unknown"
#: Columns every slipkit stream table has: a channel, label or group of the same name
#: would collide with them.
RESERVED = {"t": "time (s)", "trial_id": "trial id"}
#: Appended to "not a number" when channels are found, not listed.
_DEFAULT_CHANNELS_HINT = (
    "; without channels=[...], every column that is not the time, trial, label or "
    "group column is a channel: give text columns as label_columns or "
    "group_columns, or list channels=[...]"
)


def line_of(row: int) -> int:
    """File line (1-based; the header is line 1) of data row ``row`` (0-based)."""
    return int(row) + 2


def _delimiter_hint(sample: str, delimiter: str, option: str | None) -> str:
    """``"; is the delimiter ';'? set source.delimiter=';'"`` when ``sample`` (the first
    lines) splits cleanly on another delimiter (:class:`csv.Sniffer`); else ``""``."""
    try:
        found = csv.Sniffer().sniff(sample, delimiters=",;\t|").delimiter
    except csv.Error:
        return ""
    if found == delimiter:
        return ""
    if option is None:
        return f"; is the delimiter {found!r}?"
    # quoted for the shell: Hydra's override grammar needs ';' inside quotes
    return f'; is the delimiter {found!r}? set "{option}={found!r}"'


def _first_lines(file: Path, encoding: str, n: int = 3) -> list[str]:
    """The first ``n`` lines of ``file`` (each read up to 1 MiB: only their start is needed)."""
    lines = []
    with file.open(encoding=encoding, newline="") as handle:
        for _ in range(n):
            line = handle.readline(1 << 20)
            if not line:
                break
            lines.append(line)
    return lines


def _check_second_line(
    file: Path, delimiter: str, encoding: str, option: str | None
) -> None:
    """Refuse a first data row with more fields than the header before pandas reads it.

    pandas takes the extra leading fields of that row as an index (silently), and a
    row of millions of fields as millions of index levels: minutes and gigabytes
    before a MemoryError. The header and the first row are read here with the
    :mod:`csv` module (quotes respected; each line read up to 1 MiB at most).
    """
    lines = _first_lines(file, encoding)
    if len(lines) < 2:
        return
    try:
        header, row = csv.reader(lines[:2], delimiter=delimiter)
    except (csv.Error, ValueError):  # a field over csv's size limit: pandas reports it
        return
    if len(row) > len(header):
        cut = not lines[1].endswith(("\n", "\r"))  # read up to 1 MiB only
        more = "at least " if cut else ""
        raise SourceFormatError(
            f"{file}: line 2 has {more}{len(row)} fields but the header (line 1) has "
            f"{len(header)}; every row needs as many fields as the header"
            f"{_delimiter_hint(''.join(lines), delimiter, option)}"
        )


def read_csv_file(
    file: Path,
    *,
    delimiter: str = ",",
    decimal: str = ".",
    encoding: str = "utf-8",
    delimiter_option: str | None = None,
) -> pd.DataFrame:
    """Read one CSV with a header line, naming the file on any parse failure.

    Blank lines are kept as rows while parsing so that row ``i`` is always file
    line ``i + 2`` (see :func:`line_of`); blank lines at the end are dropped.

    Parameters
    ----------
    delimiter, decimal : str
        Field separator and decimal mark, one character each (European exports:
        ``;`` and ``,``).
    encoding : str
        Text encoding of the file (``utf-8``, ``latin-1``, ``cp1252``...).
    delimiter_option : str, optional
        The option that sets ``delimiter`` (``source.delimiter``), named in the hint
        when a row has the wrong number of fields and another delimiter fits.

    Raises
    ------
    SourceFormatError
        The file is missing, empty, not text in ``encoding``, or has a row with more
        fields than the header (the message names the line).
    """
    try:
        _check_second_line(file, delimiter, encoding, delimiter_option)
        df = pd.read_csv(
            file,
            sep=delimiter,
            decimal=decimal,
            encoding=encoding,
            skip_blank_lines=False,
        )
    except FileNotFoundError as exc:
        raise SourceFormatError(f"{file}: no such file") from exc
    except IsADirectoryError as exc:
        raise SourceFormatError(f"{file}: is a folder; expected a CSV file") from exc
    except pd.errors.EmptyDataError as exc:
        raise SourceFormatError(
            f"{file}: is empty; expected a header line and data rows"
        ) from exc
    except pd.errors.ParserError as exc:
        detail = str(exc).strip().replace("Error tokenizing data. C error: ", "")
        sample = "".join(_first_lines(file, encoding))
        raise SourceFormatError(
            f"{file}: malformed CSV ({detail}); every row needs as many fields as "
            f"the header{_delimiter_hint(sample, delimiter, delimiter_option)}"
        ) from exc
    except UnicodeDecodeError as exc:
        raise SourceFormatError(
            f"{file}: is not {encoding} text ({exc}); give the file's encoding"
            + (" (source.encoding=latin-1, cp1252...)" if delimiter_option else "")
        ) from exc
    if not df.index.equals(pd.RangeIndex(len(df))):
        # pandas takes the first field(s) as an index, silently, when *every* data
        # row has more fields than the header: the columns would shift by one.
        raise SourceFormatError(
            f"{file}: line 2 has {len(df.columns) + df.index.nlevels} fields but the "
            f"header (line 1) has {len(df.columns)}; every row needs as many fields "
            "as the header"
        )
    _check_header_names(file, delimiter, encoding)
    filled = df.notna().any(axis=1).to_numpy()
    n_keep = int(np.flatnonzero(filled)[-1]) + 1 if filled.any() else 0
    return df.iloc[:n_keep]


def _check_header_names(
    file: Path, delimiter: str = ",", encoding: str = "utf-8"
) -> None:
    """Refuse empty or repeated names in the header line.

    pandas renames them silently (``Unnamed: 2``, ``fx.1``), so the header is read
    again as text (one line) to see the names as written.
    """
    raw = pd.read_csv(
        file,
        header=None,
        nrows=1,
        dtype=str,
        keep_default_na=False,
        index_col=False,
        sep=delimiter,
        encoding=encoding,
    )
    names = ["" if pd.isna(v) else str(v) for v in raw.iloc[0].tolist()]
    seen: dict[str, int] = {}
    for pos, name in enumerate(names, start=1):
        if not name.strip():
            raise SourceFormatError(
                f"{file}: line 1, column {pos}: empty column name; every column of "
                "the header needs a name"
            )
        if name in seen:
            raise SourceFormatError(
                f"{file}: line 1, column {pos}: column name {name!r} repeats column "
                f"{seen[name]}; column names must be unique"
            )
        seen[name] = pos


def check_header(file: Path, actual: Iterable[Any], expected: Sequence[str]) -> None:
    """Check that a header is exactly ``expected``, naming the first differing column.

    Raises
    ------
    SourceFormatError
        Naming the file, the 1-based column position, the name found and the
        name expected.
    """
    found = [str(c) for c in actual]
    want = list(expected)
    if found == want:
        return
    for pos, (have, need) in enumerate(zip(found, want, strict=False), start=1):
        if have != need:
            raise SourceFormatError(
                f"{file}: header column {pos} is {have!r}; expected {need!r} "
                f"(expected header: {_abbrev(want)}, {len(want)} columns)"
            )
    raise SourceFormatError(
        f"{file}: header has {len(found)} columns; expected {len(want)} "
        f"({_abbrev(want)})"
    )


def numeric_block(
    file: Path, df: pd.DataFrame, columns: Sequence[str], *, hint: str = ""
) -> np.ndarray:
    """The given columns as a float64 array, every value finite.

    Parameters
    ----------
    hint : str
        Appended to the message of a value that is not a number (what to do).

    Raises
    ------
    SourceFormatError
        Naming the file, line and column of the first value that is not a number
        (text such as ``abc``, ``1,5``, ``0x10``, or ``True``/``False``), or of the
        first missing value (an empty field or a short row).
    """
    cols = list(columns)
    for col in cols:
        series = df[col]
        if pd.api.types.is_bool_dtype(series):
            # pandas reads a column of True/False as bool, which would pass as 1/0.
            row = int(np.flatnonzero(series.notna().to_numpy())[0])
            raise SourceFormatError(
                f"{file}: line {line_of(row)}, column {col!r}: "
                f"{bool(series.iloc[row])!r} is not a number (write 1/0){hint}"
            )
        if not pd.api.types.is_numeric_dtype(series):
            coerced = pd.to_numeric(series, errors="coerce")
            bad = np.flatnonzero((coerced.isna() & series.notna()).to_numpy())
            if len(bad):
                row = int(bad[0])
                raise SourceFormatError(
                    f"{file}: line {line_of(row)}, column {col!r}: "
                    f"{series.iloc[row]!r} is not a number{hint}"
                )
    values = df.loc[:, cols].apply(pd.to_numeric).to_numpy(dtype=np.float64)
    bad_cells = ~np.isfinite(values)
    if bad_cells.any():
        row, pos = (int(i) for i in np.argwhere(bad_cells)[0])
        raise SourceFormatError(
            f"{file}: line {line_of(row)}, column {cols[pos]!r}: missing or "
            "non-finite value (an empty field, or a row shorter than the header)"
        )
    return values


def _abbrev(names: Sequence[str], keep: int = 3) -> str:
    if len(names) <= 2 * keep:
        return ", ".join(names)
    return ", ".join([*names[:keep], "...", *names[-keep:]])


def _id_text(value: Any) -> str:
    """Trial-column value as text: integral floats lose their ``.0``."""
    if isinstance(value, float | np.floating) and float(value).is_integer():
        return str(int(value))
    return str(value)


def _list_files(path: Path, glob: str) -> tuple[list[Path], Path | None]:
    """The CSV files to read, and the folder ids are relative to (None: one file)."""
    if path.is_file():
        return [path], None
    if not path.is_dir():
        raise SourceFormatError(f"{path}: no such file or folder")
    files = sorted(p for p in path.glob(glob) if p.is_file())
    if not files:
        raise SourceFormatError(f"{path}: no files match glob {glob!r}")
    return files, path


class _Roles:
    """Which columns play which part, checked once against the arguments."""

    def __init__(
        self,
        time_column: str | None,
        trial_column: str | None,
        label_columns: Sequence[str],
        group_columns: Sequence[str],
    ) -> None:
        self.time = time_column
        self.trial = trial_column
        self.labels = tuple(str(c) for c in label_columns)
        self.groups = tuple(str(c) for c in group_columns)
        named: list[tuple[str, str]] = [
            *(("label_columns", c) for c in self.labels),
            *(("group_columns", c) for c in self.groups),
        ]
        if time_column is not None:
            named.append(("time_column", time_column))
        if trial_column is not None:
            named.append(("trial_column", trial_column))
        seen: dict[str, str] = {}
        for role, col in named:
            if col in seen:
                raise SourceFormatError(
                    f"column {col!r} is given both as {seen[col]} and as {role}; "
                    "each column has one role"
                )
            seen[col] = role
        for role, col in named:
            if col in RESERVED and role in ("label_columns", "group_columns"):
                raise SourceFormatError(
                    f"{role} names {col!r}, which is slipkit's own "
                    f"{RESERVED[col]} column in every dataset; rename the column"
                )
        self.named = named

    def check_channels(self, channels: Sequence[str], file: Path | None) -> None:
        """Channels must be distinct, play no other role and avoid slipkit's names."""
        at = f"{file}: " if file is not None else "channels: "
        roles = dict((col, role) for role, col in self.named)
        seen: set[str] = set()
        for col in channels:
            if col in roles:
                raise SourceFormatError(
                    f"{at}column {col!r} is given both as channels and as "
                    f"{roles[col]}; each column has one role"
                )
            if col in seen:
                raise SourceFormatError(f"{at}channels repeats {col!r}")
            seen.add(col)
            if col in RESERVED:
                use = (
                    "time_column='t' if it holds times in s"
                    if col == "t"
                    else ("trial_column='trial_id' if it names the trials")
                )
                raise SourceFormatError(
                    f"{at}column {col!r} would be a channel named like slipkit's own "
                    f"{RESERVED[col]} column; give {use}, or leave it out of "
                    "channels=[...] (or rename it)"
                )

    @property
    def columns(self) -> set[str]:
        return {col for _, col in self.named}


def read_csv_dataset(
    path: Path | str,
    *,
    sensor: str,
    stream: str = "signal",
    time_column: str | None = None,
    rate_hz: float | None = None,
    channels: Sequence[str] | None = None,
    units: Mapping[str, str] | str | None = None,
    label_columns: Sequence[str] = (),
    group_columns: Sequence[str] = (),
    trial_column: str | None = None,
    class_labels: Mapping[str, Sequence[str]] | None = None,
    glob: str = "*.csv",
    delimiter: str = ",",
    decimal: str = ".",
    encoding: str = "utf-8",
    slipped_column: str | None = None,
    nan_onset: str = "unknown",
) -> Dataset:
    """Read CSV files with a header line into a one-stream dataset.

    Parameters
    ----------
    path : path-like
        A CSV file, or a folder whose files matching ``glob`` are read in sorted
        order.
    sensor : str
        Sensor family recorded in the dataset (``"fsr"``, ``"tactip"``...).
    stream : str
        Name of the one stream the channels go to.
    time_column : str, optional
        Column holding the sample time in seconds, taken as given (the format
        measures label times from the trial start, so write times that way).
        Must not decrease within a trial.
    rate_hz : float, optional
        Sample rate in Hz. Without ``time_column``, row ``k`` of a trial is at
        ``t = k / rate_hz`` s; with it, the nominal rate (inferred as
        ``1 / median(dt)`` when not given). Without either, the stream is a
        ``snapshot`` stream: one row per trial, ``t = 0`` s.
    channels : sequence of str, optional
        Channel columns, in order. Default: every column that is not the time,
        trial, label or group column (they must be the same in every file). Every
        channel value must be a finite number: a text cell is an error naming its
        line and column, never a reason to drop the column. No channel may be
        named ``t`` or ``trial_id`` (every stream table has those columns).
    units : mapping of str to str, or str, optional
        Unit of each channel (``"N"``, ``"V"``, ``"1"``), or one unit for all. A
        mapping may also give the unit of numeric labels. None: ``"unknown"``.
    label_columns : sequence of str
        Columns holding trial labels; constant within a trial. Numeric columns
        become numeric labels (``slip_onset_s`` and ``reference_onset_s`` in s),
        others class labels whose classes are the sorted values seen.
    group_columns : sequence of str
        Columns grouping trials (``object``, ``material``); constant within a trial.
    trial_column : str, optional
        Column whose value splits each file into trials. Trial ids are the value
        (one file) or ``<file>/<value>`` (a folder; ``<file>`` is the path relative
        to the folder without its suffix). Without it each file is one trial,
        named by that path (one file: its stem).
    class_labels : mapping of str to sequence of str, optional
        Class names of class labels, in order (values must be among them);
        values are stored as text.
    glob : str
        File pattern when ``path`` is a folder (``"**/*.csv"`` to recurse).
    delimiter : str
        Field separator, one character (``";"`` for European exports; ``"\\t"`` or
        ``"tab"`` for a tab).
    decimal : str
        Decimal mark, one character (``","`` for decimal commas).
    encoding : str
        Text encoding of the files (``"utf-8"``, ``"latin-1"``, ``"cp1252"``...).
    slipped_column : str, optional
        Column saying whether the trial slipped (1 / 0, empty: unknown), constant
        within a trial; it becomes the label ``slipped``, apart from when
        (``slip_onset_s``, whose NaN is then an unknown onset of a slip).
    nan_onset : {"unknown", "no_slip"}
        Without ``slipped_column``, what an empty ``slip_onset_s`` means: ``unknown``
        (the label ``slipped`` is NaN there) or ``no_slip`` (0); a known onset is 1.

    Returns
    -------
    Dataset
        Named after the file or folder, with provenance naming the files read.

    Raises
    ------
    SourceFormatError
        Naming the file and column (and line or trial) of malformed input: a
        missing column, an empty or repeated header name, a value that is not a
        number, a missing value, time going backwards, a label or group column
        varying within a trial, channel columns differing between files, a column
        colliding with ``t`` / ``trial_id``; or naming the argument at fault.
    """
    path = Path(path)
    _check_argument_types(
        sensor=sensor,
        stream=stream,
        glob=glob,
        time_column=time_column,
        trial_column=trial_column,
        channels=channels,
        label_columns=label_columns,
        group_columns=group_columns,
        class_labels=class_labels,
        units=units,
    )
    delimiter, decimal, encoding = _text_options(delimiter, decimal, encoding)
    # Hydra reads a column named 5 as the number 5; the header's names are text
    time_column = None if time_column is None else str(time_column)
    trial_column = None if trial_column is None else str(trial_column)
    if nan_onset not in ("unknown", "no_slip"):
        raise SourceFormatError(
            f"nan_onset is {nan_onset!r}; expected 'unknown' or 'no_slip' (what an "
            "empty slip_onset_s means)"
        )
    if slipped_column is None and SLIPPED_LABEL in label_columns:
        slipped_column = SLIPPED_LABEL  # a label of that name says it, not the onset
    label_columns = [
        *(c for c in label_columns if c != slipped_column),
        *([slipped_column] if slipped_column else []),
    ]
    roles = _Roles(time_column, trial_column, label_columns, group_columns)
    classes = {
        str(k): tuple(str(c) for c in v) for k, v in (class_labels or {}).items()
    }
    stray = sorted(set(classes) - set(roles.labels))
    if stray:
        raise SourceFormatError(
            f"class_labels names {stray}, which are not in label_columns "
            f"{list(roles.labels)}"
        )
    if rate_hz is not None and not (np.isfinite(rate_hz) and rate_hz > 0):
        raise SourceFormatError(f"rate_hz is {rate_hz!r}; expected a rate > 0 Hz")
    files, root = _list_files(path, glob)
    snapshot = time_column is None and rate_hz is None

    chans: tuple[str, ...] | None = (
        None if channels is None else tuple(str(c) for c in channels)
    )
    if chans is not None:
        if not chans:
            raise SourceFormatError("channels is empty; list at least one column")
        roles.check_channels(chans, None)
    first_file: Path | None = None
    parts: list[pd.DataFrame] = []
    rows: list[dict[str, Any]] = []
    where: dict[str, tuple[Path, int]] = {}
    steps: list[np.ndarray] = []
    for file in files:
        df = read_csv_file(
            file,
            delimiter=delimiter,
            decimal=decimal,
            encoding=encoding,
            delimiter_option="source.delimiter",
        )
        if df.empty:
            raise SourceFormatError(f"{file}: has a header but no data rows")
        df.columns = [str(c) for c in df.columns]
        for role, col in roles.named:
            if col not in df.columns:
                raise SourceFormatError(
                    f"{file}: no column {col!r} ({role}); columns are "
                    f"{_abbrev(list(df.columns))}"
                )
        if channels is None:
            # Every other column is a channel, numeric or not: picking only the
            # columns pandas read as numbers would drop a channel silently over
            # one bad cell ("abc", "1,5", "True"); numeric_block names it instead.
            found = tuple(c for c in df.columns if c not in roles.columns)
            if not found:
                raise SourceFormatError(
                    f"{file}: no channel columns besides the time, trial, label and "
                    "group columns"
                )
            roles.check_channels(found, file)
            if chans is None:
                chans, first_file = found, file
            elif found != chans:
                raise SourceFormatError(
                    f"{file}: channel columns {_abbrev(list(found))} differ from "
                    f"{_abbrev(list(chans))} in {first_file}; give channels=[...] "
                    "explicitly or make the files agree"
                )
        assert chans is not None
        for col in chans:
            if col not in df.columns:
                raise SourceFormatError(
                    f"{file}: no channel column {col!r}; columns are "
                    f"{_abbrev(list(df.columns))}"
                )
        values = numeric_block(
            file, df, chans, hint=_DEFAULT_CHANNELS_HINT if channels is None else ""
        )

        if root is None:
            file_id = file.stem
        else:
            file_id = file.relative_to(root).with_suffix("").as_posix()
        if trial_column is None:
            codes = np.zeros(len(df), dtype=np.int64)
            ids = [file_id]
        else:
            tcol = df[trial_column]
            if tcol.isna().any():
                row = int(np.flatnonzero(tcol.isna().to_numpy())[0])
                raise SourceFormatError(
                    f"{file}: line {line_of(row)}, column {trial_column!r} "
                    "(trial_column): missing trial value"
                )
            codes_raw, uniques = pd.factorize(tcol, sort=False)
            codes = np.asarray(codes_raw, dtype=np.int64)
            text = [_id_text(u) for u in uniques]
            ids = text if root is None else [f"{file_id}/{u}" for u in text]
        order = np.argsort(codes, kind="stable")
        sorted_codes = codes[order]
        counts = np.bincount(codes, minlength=len(ids))
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        first_rows = order[starts]

        if time_column is not None:
            t = numeric_block(file, df, [time_column])[:, 0][order]
            back = np.flatnonzero((np.diff(t) < 0) & (np.diff(sorted_codes) == 0))
            if len(back):
                row = int(order[back[0] + 1])
                raise SourceFormatError(
                    f"{file}: line {line_of(row)}, column {time_column!r}: time "
                    f"decreases within trial {ids[codes[row]]!r}; expected "
                    "non-decreasing seconds"
                )
            dt = np.diff(t)[np.diff(sorted_codes) == 0]
            steps.append(dt[dt > 0])
        elif rate_hz is not None:
            t = (np.arange(len(df)) - starts[sorted_codes]) / float(rate_hz)
        else:
            many = np.flatnonzero(counts > 1)
            if len(many):
                k = int(many[0])
                raise SourceFormatError(
                    f"{file}: trial {ids[k]!r} has {int(counts[k])} rows; without "
                    "time_column or rate_hz each trial is one snapshot row (give "
                    "time_column or rate_hz for a time series)"
                )
            t = np.zeros(len(df))

        for col in (*roles.labels, *roles.groups):
            nunique = df.groupby(codes, sort=True)[col].nunique(dropna=False)
            varying = np.flatnonzero(nunique.to_numpy() > 1)
            if len(varying):
                k = int(varying[0])
                members = order[sorted_codes == k]
                val_codes, _ = pd.factorize(
                    df[col].iloc[members], use_na_sentinel=False
                )
                other = int(members[np.flatnonzero(val_codes != val_codes[0])[0]])
                first = int(members[0])
                raise SourceFormatError(
                    f"{file}: column {col!r} varies within trial {ids[k]!r} "
                    f"({df[col].iloc[first]!r} at line {line_of(first)}, "
                    f"{df[col].iloc[other]!r} at line {line_of(other)}); label and "
                    "group columns must be constant within a trial"
                )

        part = pd.DataFrame(values[order], columns=list(chans))
        part.insert(0, "t", t)
        part.insert(0, "trial_id", np.asarray(ids, dtype=object)[sorted_codes])
        parts.append(part)
        for k, tid in enumerate(ids):
            first = int(first_rows[k])
            if tid in where:
                prev, prev_line = where[tid]
                raise SourceFormatError(
                    f"{file}: trial id {tid!r} (line {line_of(first)}) repeats the one "
                    f"at line {prev_line} of {prev}; trial ids must be unique"
                )
            where[tid] = (file, line_of(first))
            rows.append(
                {
                    "trial_id": tid,
                    **{c: df[c].iloc[first] for c in (*roles.groups, *roles.labels)},
                }
            )

    assert chans is not None
    unit_of = _units(units, chans)
    if snapshot:
        spec = StreamSpec(stream, chans, unit_of, rate_hz=None, kind="snapshot")
    else:
        spec = StreamSpec(stream, chans, unit_of, rate_hz=_rate(rate_hz, steps, path))
    trials = pd.DataFrame(rows, columns=["trial_id", *roles.groups, *roles.labels])
    labels = {
        name: _label_spec(name, trials, classes.get(name), units, where)
        for name in roles.labels
        if name != slipped_column
    }
    slipped = _slipped(trials, slipped_column, nan_onset, where)
    if slipped is not None:
        if slipped_column is not None:
            trials = trials.drop(columns=slipped_column)
        trials[SLIPPED_LABEL] = slipped
        labels[SLIPPED_LABEL] = LabelSpec(SLIPPED_LABEL)
    return Dataset(
        sensor=sensor,
        streams={stream: spec},
        trials=trials,
        tables={stream: pd.concat(parts, ignore_index=True)},
        labels=labels,
        groups=roles.groups,
        provenance={
            "source": str(path),
            "importer": "slipkit.data.importers.csv.read_csv_dataset",
            "files": [
                f.name if root is None else f.relative_to(root).as_posix()
                for f in files
            ],
            "options": {
                "delimiter": delimiter,
                "decimal": decimal,
                "encoding": encoding,
                "time_column": time_column,
                "rate_hz": rate_hz,
                "trial_column": trial_column,
                "label_columns": list(roles.labels),
                "group_columns": list(roles.groups),
                "slipped_column": slipped_column,
                "nan_onset": nan_onset,
            },
        },
        name=path.stem if path.is_file() else path.resolve().name,
    )


def _is_names(value: Any) -> bool:
    return isinstance(value, list | tuple) and all(
        isinstance(v, str | int) and not isinstance(v, bool) and str(v) for v in value
    )


def _check_argument_types(**given: Any) -> None:
    """Refuse an argument of the wrong kind, naming it (a text where a list belongs would
    otherwise be read letter by letter: ``label_columns='slip'`` as columns s, l, i, p)."""
    expected = {
        "sensor": ("a non-empty name", lambda v: isinstance(v, str) and v.strip()),
        "stream": ("a non-empty name", lambda v: isinstance(v, str) and v.strip()),
        "glob": (
            "a non-empty file pattern such as '*.csv'",
            lambda v: isinstance(v, str) and v,
        ),
        "time_column": ("a column name or null", lambda v: v is None or _is_names([v])),
        "trial_column": (
            "a column name or null",
            lambda v: v is None or _is_names([v]),
        ),
        "channels": (
            "a list of column names such as [fx, fy] or null",
            lambda v: v is None or _is_names(v),
        ),
        "label_columns": (
            "a list of column names such as [slip_onset_s] (or [])",
            _is_names,
        ),
        "group_columns": ("a list of column names such as [object] (or [])", _is_names),
        "class_labels": (
            "a mapping {label: [class, ...]} or null",
            lambda v: (
                v is None
                or (isinstance(v, Mapping) and all(_is_names(c) for c in v.values()))
            ),
        ),
        "units": (
            "one unit such as N, a mapping {channel: unit}, or null",
            lambda v: v is None or isinstance(v, str | Mapping),
        ),
    }
    for name, value in given.items():
        text, ok = expected[name]
        if not ok(value):
            shown = "null" if value is None else repr(value)
            raise SourceFormatError(f"{name}={shown}: expected {text}")


def _text_options(delimiter: Any, decimal: Any, encoding: Any) -> tuple[str, str, str]:
    """The CSV text options checked: one-character delimiter and decimal mark, a known encoding."""
    if delimiter in ("\\t", "tab"):
        delimiter = "\t"
    if not (
        isinstance(delimiter, str)
        and len(delimiter) == 1
        and delimiter not in "\r\n\"'"
    ):
        raise SourceFormatError(
            f"delimiter={delimiter!r}: expected one character such as ',' ';' '|' or '\\t'"
        )
    if not (isinstance(decimal, str) and len(decimal) == 1 and decimal not in "\r\n"):
        raise SourceFormatError(
            f"decimal={decimal!r}: expected one character, '.' or ','"
        )
    if decimal == delimiter:
        raise SourceFormatError(
            f"decimal={decimal!r}: the same character as delimiter; give another one"
        )
    try:
        codecs.lookup(str(encoding))
    except LookupError:
        raise SourceFormatError(
            f"encoding={encoding!r}: unknown text encoding; e.g. utf-8, latin-1, cp1252"
        ) from None
    return delimiter, decimal, str(encoding)


def _units(
    units: Mapping[str, str] | str | None, chans: Sequence[str]
) -> dict[str, str]:
    if units is None:
        return dict.fromkeys(chans, UNKNOWN_UNIT)
    if isinstance(units, str):
        return dict.fromkeys(chans, units)
    missing = [c for c in chans if c not in units]
    if missing:
        raise SourceFormatError(
            f"units: no unit for channels {missing}; give a unit for every channel, "
            "or one string for all"
        )
    return {c: str(units[c]) for c in chans}


def _rate(rate_hz: float | None, steps: list[np.ndarray], path: Path) -> float:
    """The given rate, or ``1 / median(dt)`` in Hz over every trial's time steps."""
    if rate_hz is not None:
        return float(rate_hz)
    dt = np.concatenate(steps) if steps else np.empty(0)
    if dt.size == 0:
        raise SourceFormatError(
            f"{path}: cannot infer a sample rate from the time column (no trial has "
            "two distinct times); give rate_hz"
        )
    return float(round(1.0 / float(np.median(dt)), 6))


def _slipped(
    trials: pd.DataFrame,
    column: str | None,
    nan_onset: str,
    where: Mapping[str, tuple[Path, int]],
) -> np.ndarray | None:
    """The ``slipped`` label per trial (1, 0, NaN: unknown), or None when the data says
    nothing of slip (no ``slipped_column`` and no ``slip_onset_s``).

    From ``column`` (values 0 / 1 / empty; 0 beside a known onset is refused), else from
    ``slip_onset_s``: 1 where known, ``nan_onset`` (NaN or 0) where empty.
    """
    onset = (
        pd.to_numeric(trials["slip_onset_s"], errors="coerce").to_numpy(np.float64)
        if "slip_onset_s" in trials
        else None
    )
    if column is None:
        if onset is None:
            return None
        empty = 0.0 if nan_onset == "no_slip" else np.nan
        return np.where(np.isfinite(onset), 1.0, empty)
    values = pd.to_numeric(trials[column], errors="coerce").to_numpy(np.float64)
    for k, (raw, v) in enumerate(zip(trials[column], values, strict=True)):
        known = not pd.isna(raw)
        bad = known and v not in (0.0, 1.0)
        contradiction = v == 0.0 and onset is not None and bool(np.isfinite(onset[k]))
        if bad or contradiction:
            file, line = where[str(trials["trial_id"].iloc[k])]
            raise SourceFormatError(
                f"{file}: line {line}, column {column!r} (slipped_column): "
                + (
                    f"{_id_text(raw)} is not 1 (slipped), 0 (did not slip) or empty (unknown)"
                    if bad
                    else "0 (did not slip) beside a slip_onset_s of "
                    f"{onset[k]:g} s; a trial with an onset slipped"  # type: ignore[index]
                )
            )
    return values


def _label_spec(
    name: str,
    trials: pd.DataFrame,
    classes: tuple[str, ...] | None,
    units: Mapping[str, str] | str | None,
    where: Mapping[str, tuple[Path, int]],
) -> LabelSpec:
    """Spec of one label column; class labels are rewritten as text in ``trials``."""
    col = trials[name]
    if classes is None and pd.api.types.is_numeric_dtype(col):
        unit = None
        if isinstance(units, Mapping) and name in units:
            unit = str(units[name])
        elif name in STANDARD_LABELS and name.endswith("_s"):
            unit = "s"
        return LabelSpec(name, unit=unit)
    known = col.notna()
    text = col.where(~known, col.map(_id_text))
    trials[name] = text.astype(object)
    if classes is None:
        return LabelSpec(name, classes=tuple(sorted(set(text[known]))))
    outside = np.flatnonzero((known & ~text.isin(classes)).to_numpy())
    if len(outside):
        k = int(outside[0])
        file, line = where[str(trials["trial_id"].iloc[k])]
        raise SourceFormatError(
            f"{file}: line {line}, column {name!r}: value {text.iloc[k]!r} is not "
            f"one of its class_labels {list(classes)}"
        )
    return LabelSpec(name, classes=classes)
