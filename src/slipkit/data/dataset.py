"""Trial and Dataset: the one in-memory form of recorded and simulated data.

A :class:`Dataset` keeps every stream as one *long* table (``trial_id``, ``t`` in
seconds, then the channels) plus a ``trials`` table with one row per trial (group
columns such as ``object`` and scalar labels such as ``slip_onset_s``). That is
exactly the on-disk layout (see ``docs/dataset-format.md``), so loading is a read
and iterating yields :class:`Trial` views without copying the whole dataset.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd

from slipkit.errors import DatasetError

FORMAT = "slipkit-dataset"
SCHEMA_VERSION = 1

StreamKind = Literal["sampled", "events", "snapshot"]
STREAM_KINDS: tuple[str, ...] = ("sampled", "events", "snapshot")

#: Label names with a fixed meaning across slipkit (any other name is allowed).
STANDARD_LABELS: dict[str, str] = {
    "slip_onset_s": "true slip onset, s from the trial start (NaN: no slip, or onset not recorded: the label 'slipped' says which)",
    "slipped": "did the trial slip: 1 or 0 (NaN: unknown); without this label a NaN onset means no slip",
    "reference_onset_s": "onset seen by a late reference sensor (e.g. object IMU), s",
    "slip_class": "class of the trial (e.g. linear / rotational / touch)",
}


@dataclass(frozen=True)
class StreamSpec:
    """What one stream holds.

    Parameters
    ----------
    name : str
        Stream name, also its file name (``streams/<name>.parquet``).
    channels : tuple of str
        Channel columns, in order (``t`` and ``trial_id`` are implicit).
    units : mapping of str to str
        Unit of each channel (``"N"``, ``"V"``, ``"mm"``, ``"1"`` when unitless).
    rate_hz : float or None
        Nominal sample rate in Hz; None for event and snapshot streams.
    kind : {"sampled", "events", "snapshot"}
        ``sampled``: regular frames; ``events``: asynchronous rows (DAVIS);
        ``snapshot``: one frame per trial (a reading taken before lifting).
    description : str
        One line on what the stream measures.
    """

    name: str
    channels: tuple[str, ...]
    units: Mapping[str, str]
    rate_hz: float | None = None
    kind: StreamKind = "sampled"
    description: str = ""

    def __post_init__(self) -> None:
        where = f"stream '{self.name}'"
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "units", dict(self.units))
        if not self.name or "/" in self.name:
            raise DatasetError(
                where, "stream names must be non-empty and contain no '/'"
            )
        if not self.channels:
            raise DatasetError(
                where, "field 'channels' is empty; expected >= 1 channel"
            )
        reserved = {"trial_id", "t"} & set(self.channels)
        if reserved:
            raise DatasetError(where, f"channel names {sorted(reserved)} are reserved")
        if len(set(self.channels)) != len(self.channels):
            raise DatasetError(where, "field 'channels' repeats a name")
        missing = [c for c in self.channels if c not in self.units]
        if missing:
            raise DatasetError(
                where, f"field 'units' has no unit for channels {missing}"
            )
        if self.kind not in STREAM_KINDS:
            raise DatasetError(
                where, f"field 'kind' is {self.kind!r}; expected one of {STREAM_KINDS}"
            )
        if self.kind == "sampled":
            if (
                self.rate_hz is None
                or not np.isfinite(self.rate_hz)
                or self.rate_hz <= 0
            ):
                raise DatasetError(
                    where,
                    f"field 'rate_hz' is {self.rate_hz!r}; a sampled stream needs a rate > 0 Hz",
                )
        elif self.rate_hz is not None:
            raise DatasetError(
                where, f"field 'rate_hz' must be null for a {self.kind} stream"
            )

    def to_json(self) -> dict[str, Any]:
        """The manifest entry of this stream."""
        return {
            "kind": self.kind,
            "rate_hz": self.rate_hz,
            "channels": list(self.channels),
            "units": {c: self.units[c] for c in self.channels},
            "description": self.description,
        }

    @classmethod
    def from_json(
        cls, name: str, entry: Mapping[str, Any], where: str = "manifest.json"
    ) -> StreamSpec:
        """Build from a manifest entry, naming the missing field on error."""
        for key in ("kind", "rate_hz", "channels", "units"):
            if key not in entry:
                raise DatasetError(where, f"streams.{name}: missing field '{key}'")
        rate = entry["rate_hz"]
        channels = tuple(entry["channels"])
        extra = sorted(set(entry["units"]) - set(channels))
        if extra:
            raise DatasetError(
                where,
                f"streams.{name}.units: gives units for {extra}, which are not among "
                f"its channels {list(channels)}",
            )
        try:
            return cls(
                name=name,
                channels=channels,
                units=dict(entry["units"]),
                rate_hz=None if rate is None else float(rate),
                kind=entry["kind"],
                description=str(entry.get("description", "")),
            )
        except DatasetError as exc:  # name the file, and the field under 'streams'
            raise DatasetError(where, f"streams.{name}: {exc.problem}") from exc


@dataclass(frozen=True)
class LabelSpec:
    """A trial-level label column: its unit, or its class names for a class label."""

    name: str
    unit: str | None = None
    classes: tuple[str, ...] | None = None
    description: str = ""

    def __post_init__(self) -> None:
        if self.classes is not None:
            object.__setattr__(self, "classes", tuple(self.classes))
        if not self.description:
            object.__setattr__(self, "description", STANDARD_LABELS.get(self.name, ""))

    def to_json(self) -> dict[str, Any]:
        return {
            "unit": self.unit,
            "classes": None if self.classes is None else list(self.classes),
            "description": self.description,
        }

    @classmethod
    def from_json(cls, name: str, entry: Mapping[str, Any]) -> LabelSpec:
        classes = entry.get("classes")
        return cls(
            name=name,
            unit=entry.get("unit"),
            classes=None if classes is None else tuple(classes),
            description=str(entry.get("description", "")),
        )


@dataclass
class Trial:
    """One recording.

    Attributes
    ----------
    trial_id : str
        Unique within its dataset.
    streams : dict of str to DataFrame
        Each a table with column ``t`` (s) and the stream's channels.
    labels : dict
        Scalar labels (``slip_onset_s`` in s, ``slip_class``, ...).
    meta : dict
        Group columns (``object``, ``material``...) and ``sensor``.
    specs : dict of str to StreamSpec
        Rates, channels and units of each stream.
    """

    trial_id: str
    streams: dict[str, pd.DataFrame]
    labels: dict[str, Any] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    specs: dict[str, StreamSpec] = field(default_factory=dict)

    def duration_s(self) -> float:
        """Longest time span over the trial's streams, in seconds."""
        spans = [
            float(df["t"].iloc[-1] - df["t"].iloc[0])
            for df in self.streams.values()
            if len(df)
        ]
        return max(spans, default=0.0)


def _table_digest(table: pd.DataFrame) -> bytes:
    """Row hashes of a table; text columns are cast to ``str`` first so that object and
    pandas string dtypes (which a Parquet round trip may swap) hash alike."""
    as_text = {c: str for c in table.columns if not _is_numeric(table[c])}
    hashed = pd.util.hash_pandas_object(table.astype(as_text), index=False)
    return hashed.to_numpy().tobytes()


def _is_numeric(series: pd.Series) -> bool:
    return pd.api.types.is_numeric_dtype(series) or pd.api.types.is_bool_dtype(series)


def _check_table(
    spec: StreamSpec, table: pd.DataFrame, where: str, trial_ids: set[str]
) -> pd.DataFrame:
    """Check one long stream table against its spec; return it with a clean index."""
    expected = ["trial_id", "t", *spec.channels]
    missing = [c for c in expected if c not in table.columns]
    if missing:
        raise DatasetError(
            where, f"missing columns {missing}; expected columns {expected}"
        )
    extra = [c for c in table.columns if c not in expected]
    if extra:
        raise DatasetError(
            where, f"unexpected columns {extra}; the manifest declares {expected}"
        )
    table = table.loc[:, expected].reset_index(drop=True)
    for col in ["t", *spec.channels]:
        if pd.api.types.is_bool_dtype(table[col]):
            # true/false would pass as 1/0 and train as a signal nobody recorded
            raise DatasetError(
                where,
                f"column {col!r} holds true/false values (dtype {table[col].dtype}); "
                "expected numbers (write 1/0 if it is a measured on/off signal)",
            )
        if not _is_numeric(table[col]):
            raise DatasetError(
                where,
                f"column {col!r} has dtype {table[col].dtype}; expected a numeric dtype",
            )
    t = table["t"].to_numpy(dtype=np.float64)
    if not np.all(np.isfinite(t)):
        row = int(np.flatnonzero(~np.isfinite(t))[0])
        raise DatasetError(
            where,
            f"column 't' is not finite at row {row} (trial {table['trial_id'].iloc[row]!r})",
        )
    if not pd.api.types.is_string_dtype(table["trial_id"]):
        table["trial_id"] = table["trial_id"].astype(str)
    # pd.factorize: integer codes without sorting strings (np.unique on 1e6 string
    # ids costs ~50x more and dominated simulation time).
    codes, uniques = pd.factorize(table["trial_id"], sort=False)
    if len(codes):
        unknown = set(map(str, uniques)) - trial_ids
        if unknown:
            raise DatasetError(
                where,
                f"column 'trial_id' names trials not in trials.parquet: {sorted(unknown)[:5]}",
            )
        same = codes[1:] == codes[:-1]
        if int(np.count_nonzero(~same)) + 1 != len(uniques):
            raise DatasetError(
                where,
                "rows of one trial are not contiguous; expected rows grouped by 'trial_id'",
            )
        backwards = same & (np.diff(t) < 0)
        if backwards.any():
            row = int(np.flatnonzero(backwards)[0]) + 1
            raise DatasetError(
                where,
                f"column 't' decreases at row {row} (trial {uniques[codes[row]]!r}); expected non-decreasing time within a trial",
            )
        if spec.kind == "snapshot":
            counts = np.bincount(codes)
            if counts.max() > 1:
                raise DatasetError(
                    where,
                    f"snapshot stream has {int(counts.max())} rows for trial {uniques[int(counts.argmax())]!r}; expected 1",
                )
    return table


def _check_numeric_label(column: pd.Series, spec: LabelSpec, where: str) -> None:
    """A label without classes is a number per trial (NaN: unknown); refuse text."""
    if _is_numeric(column) or column.isna().all():
        return
    numbers = pd.to_numeric(column, errors="coerce")
    bad = np.flatnonzero((numbers.isna() & column.notna()).to_numpy())
    if not len(bad):
        return  # numbers held as objects (e.g. floats mixed with None)
    row = int(bad[0])
    unit = f"unit {spec.unit!r}" if spec.unit is not None else "no unit"
    raise DatasetError(
        where,
        f"column {spec.name!r} holds {column.iloc[row]!r} at row {row}; the "
        f"manifest declares label {spec.name!r} numeric "
        f"({unit}, no classes), so every value must be a number or NaN",
    )


class Dataset:
    """A set of trials from one sensor, in slipkit's exchange format.

    Parameters
    ----------
    sensor : str
        Sensor family (``tactip``, ``biotac``, ``biotac_sp``, ``fsr``, ``sliptack``, ``davis``...).
    streams : mapping of str to StreamSpec
        The streams every trial may hold.
    trials : DataFrame
        One row per trial: ``trial_id`` then group and label columns.
    tables : mapping of str to DataFrame
        One long table per stream: ``trial_id``, ``t`` (s), channels.
    labels : mapping of str to LabelSpec, optional
        Which columns of ``trials`` are labels (the others are groups/metadata).
    groups : sequence of str
        Columns of ``trials`` that group trials (``object``, ``material``); splits use them.
    provenance : mapping, optional
        Where the data came from: ``{"scene": ..., "params": ..., "seed": ...}`` for
        simulated data, ``{"source": ..., "citation": ..., "files": ...}`` for recordings.
    name : str, optional
        A short name for reports.
    sources : mapping of str to str, optional
        What to call each table in error messages (the loader passes file names).
    """

    def __init__(
        self,
        *,
        sensor: str,
        streams: Mapping[str, StreamSpec],
        trials: pd.DataFrame,
        tables: Mapping[str, pd.DataFrame],
        labels: Mapping[str, LabelSpec] | None = None,
        groups: Sequence[str] = (),
        provenance: Mapping[str, Any] | None = None,
        name: str = "",
        sources: Mapping[str, str] | None = None,
    ) -> None:
        sources = dict(sources or {})
        twhere = sources.get("trials", "trials table")
        if "trial_id" not in trials.columns:
            raise DatasetError(twhere, "missing column 'trial_id'")
        trials = trials.reset_index(drop=True).copy()
        trials["trial_id"] = trials["trial_id"].astype(str)
        dup = trials["trial_id"][trials["trial_id"].duplicated()]
        if len(dup):
            raise DatasetError(
                twhere,
                f"column 'trial_id' repeats {dup.iloc[0]!r}; trial ids must be unique",
            )
        self.labels: dict[str, LabelSpec] = dict(labels or {})
        both = sorted(set(self.labels) & set(groups))
        if both or "trial_id" in [*self.labels, *groups]:
            raise DatasetError(
                twhere,
                f"column {(both or ['trial_id'])[0]!r} cannot be "
                + ("both a label and a group" if both else "a label or a group"),
            )
        for col in [*self.labels, *groups]:
            if col not in trials.columns:
                raise DatasetError(
                    twhere, f"missing column {col!r} declared in the manifest"
                )
        for lab in self.labels.values():
            if lab.classes is None:
                _check_numeric_label(trials[lab.name], lab, twhere)
            else:
                values = trials[lab.name].dropna().astype(str)
                unknown = sorted(set(values) - set(lab.classes))
                if unknown:
                    raise DatasetError(
                        twhere,
                        f"column {lab.name!r} holds {unknown[:5]} outside its classes {list(lab.classes)}",
                    )
        if set(streams) != set(tables):
            raise DatasetError(
                "dataset",
                f"streams declared {sorted(streams)} but tables given for {sorted(tables)}",
            )
        ids = set(trials["trial_id"])
        self.sensor = str(sensor)
        self.name = str(name)
        self.streams: dict[str, StreamSpec] = dict(streams)
        self.groups: tuple[str, ...] = tuple(groups)
        self.provenance: dict[str, Any] = dict(provenance or {})
        self.trials: pd.DataFrame = trials
        self.tables: dict[str, pd.DataFrame] = {
            s: _check_table(streams[s], tables[s], sources.get(s, f"stream '{s}'"), ids)
            for s in streams
        }
        self._index: dict[str, dict[str, np.ndarray]] = {}

    # -- construction --------------------------------------------------------------
    @classmethod
    def from_trials(
        cls,
        trials: Iterable[Trial],
        *,
        sensor: str,
        streams: Mapping[str, StreamSpec],
        labels: Mapping[str, LabelSpec] | None = None,
        groups: Sequence[str] = (),
        provenance: Mapping[str, Any] | None = None,
        name: str = "",
    ) -> Dataset:
        """Assemble a dataset from :class:`Trial` objects (e.g. one per simulated run)."""
        rows: list[dict[str, Any]] = []
        parts: dict[str, list[pd.DataFrame]] = {s: [] for s in streams}
        owners: dict[str, list[str]] = {s: [] for s in streams}
        for trial in trials:
            rows.append({"trial_id": trial.trial_id, **trial.meta, **trial.labels})
            for s, df in trial.streams.items():
                if s not in parts:
                    raise DatasetError(
                        f"trial {trial.trial_id!r}",
                        f"stream '{s}' is not declared; declared: {sorted(streams)}",
                    )
                parts[s].append(df)
                owners[s].append(trial.trial_id)
        table = pd.DataFrame(rows)
        table = table.drop(columns=[c for c in ("sensor",) if c in table.columns])
        if table.empty:
            table = pd.DataFrame({"trial_id": pd.Series([], dtype=str)})
        tables = {}
        for s, spec in streams.items():
            if parts[s]:
                # One concat and one id column per stream: inserting the id into every
                # trial's frame cost more than simulating short trials.
                lengths = [len(df) for df in parts[s]]
                table_s = pd.concat(parts[s], ignore_index=True)
                table_s.insert(
                    0,
                    "trial_id",
                    np.repeat(np.asarray(owners[s], dtype=object), lengths),
                )
                tables[s] = table_s
            else:
                tables[s] = pd.DataFrame(
                    {c: pd.Series([], dtype=float) for c in ["t", *spec.channels]}
                ).assign(trial_id=pd.Series([], dtype=str))
        return cls(
            sensor=sensor,
            streams=streams,
            trials=table,
            tables=tables,
            labels=labels,
            groups=groups,
            provenance=provenance,
            name=name,
        )

    # -- access ----------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.trials)

    @property
    def trial_ids(self) -> list[str]:
        return self.trials["trial_id"].tolist()

    def _rows(self, stream: str) -> dict[str, np.ndarray]:
        if stream not in self._index:
            groups = self.tables[stream].groupby("trial_id", sort=False).indices
            self._index[stream] = {str(k): np.asarray(v) for k, v in groups.items()}
        return self._index[stream]

    def trial(self, trial_id: str) -> Trial:
        """The trial called ``trial_id``."""
        match = self.trials.index[self.trials["trial_id"] == trial_id]
        if len(match) == 0:
            raise KeyError(
                f"no trial {trial_id!r} in dataset {self.name or self.sensor!r}"
            )
        return self._make_trial(self.trials.iloc[int(match[0])])

    __getitem__ = trial

    def _make_trial(self, row: pd.Series) -> Trial:
        tid = str(row["trial_id"])
        streams = {}
        for s, table in self.tables.items():
            idx = self._rows(s).get(tid)
            if idx is None:
                continue
            streams[s] = table.iloc[idx].drop(columns="trial_id").reset_index(drop=True)
        labels = {k: row[k] for k in self.labels}
        meta = {
            k: row[k] for k in row.index if k != "trial_id" and k not in self.labels
        }
        meta["sensor"] = self.sensor
        return Trial(
            trial_id=tid,
            streams=streams,
            labels=labels,
            meta=meta,
            specs=dict(self.streams),
        )

    def __iter__(self) -> Iterator[Trial]:
        for _, row in self.trials.iterrows():
            yield self._make_trial(row)

    def stream(self, name: str) -> pd.DataFrame:
        """The long table of one stream (``trial_id``, ``t``, channels)."""
        if name not in self.tables:
            raise KeyError(f"no stream {name!r}; streams are {sorted(self.tables)}")
        return self.tables[name]

    def to_frames(self) -> tuple[pd.DataFrame, dict[str, pd.DataFrame]]:
        """The trials table and every stream's long table, for analysis in pandas.

        Each stream table gets the trials' group and label columns joined on.
        """
        return self.trials.copy(), {
            s: table.merge(self.trials, on="trial_id", how="left")
            for s, table in self.tables.items()
        }

    def subset(self, trial_ids: Iterable[str], *, name: str | None = None) -> Dataset:
        """A new dataset with only the given trials (in this dataset's order)."""
        keep = set(map(str, trial_ids))
        unknown = keep - set(self.trials["trial_id"])
        if unknown:
            raise KeyError(f"unknown trial ids {sorted(unknown)[:5]}")
        return Dataset(
            sensor=self.sensor,
            streams=self.streams,
            trials=self.trials[self.trials["trial_id"].isin(keep)],
            tables={s: t[t["trial_id"].isin(keep)] for s, t in self.tables.items()},
            labels=self.labels,
            groups=self.groups,
            provenance=self.provenance,
            name=self.name if name is None else name,
        )

    def class_names(self, label: str = "slip_class") -> tuple[str, ...]:
        """Declared class names of a class label."""
        spec = self.labels.get(label)
        if spec is None or spec.classes is None:
            raise KeyError(
                f"{label!r} is not a class label of this dataset; labels: {sorted(self.labels)}"
            )
        return spec.classes

    def fingerprint(self) -> str:
        """A sha256 of the content (tables and specs), stable across save and load.

        Bundles record it so a deployed model names the data it was trained on.
        """
        digest = hashlib.sha256()
        digest.update(
            json.dumps(self._spec_json(), sort_keys=True, default=str).encode()
        )
        for key, table in [("trials", self.trials), *sorted(self.tables.items())]:
            digest.update(key.encode())
            digest.update(_table_digest(table))
        return digest.hexdigest()

    def _spec_json(self) -> dict[str, Any]:
        return {
            "sensor": self.sensor,
            "streams": {s: spec.to_json() for s, spec in sorted(self.streams.items())},
            "labels": {k: v.to_json() for k, v in sorted(self.labels.items())},
            "groups": list(self.groups),
        }

    def __repr__(self) -> str:
        streams = ", ".join(
            f"{s}[{len(spec.channels)}ch@{spec.rate_hz or spec.kind}]"
            for s, spec in self.streams.items()
        )
        return f"Dataset({self.name or '?'}: sensor={self.sensor}, trials={len(self)}, streams: {streams})"
