"""ROS bags (ROS 1 ``.bag``; ROS 2 in MCAP or sqlite3 storage) into a slipkit dataset.

Bags are read with the ``rosbags`` library (pure Python: no ROS install), imported
only inside :func:`read_rosbag`, so nothing else in slipkit (least of all the
runtime) loads it. Each named topic becomes one sampled stream:

- numeric message fields become channels named by their field path
  (``wrench.force.x``); arrays become ``<field>_<i>``; a ``std_msgs`` ``*MultiArray``
  gives only its ``data`` array (``data_0``, ``data_1``...); a ``std_msgs/Header``
  is never a channel (it is the time);
- a sample's time is its message's ``header.stamp`` when the message has a header
  (``stamp="header"``, the default), else the time the bag recorded it;
- ``t`` is in seconds from the trial start: for a whole-bag trial, the earliest
  sample time of the imported topics in that bag;
- the rate of a stream is ``1 / median(dt)`` over the time steps of every trial
  (rounded to 6 decimals, as the CSV importer does).

Trials are one per bag, or cut by a table of ``(bag, trial, t_start_s, t_end_s)``
(seconds from the bag's first sample) or by a marker topic (``std_msgs/Bool``: true
starts a trial, false ends it; ``std_msgs/String``: a text starts a trial named by
it, an empty text ends it). Labels and groups come from ``labels.csv`` beside the
bags (see :func:`read_rosbag`). See ``docs/importers.md``.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import STANDARD_LABELS, Dataset, LabelSpec, StreamSpec
from slipkit.data.importers.csv import (
    _label_spec,  # the CSV importer's label rules (numeric vs class, units), reused as-is
    line_of,
    numeric_block,
    read_csv_file,
)
from slipkit.errors import SlipkitError, SourceFormatError

__all__ = ["BAG_SUFFIXES", "LABELS_FILE", "read_rosbag"]

#: File suffixes read as bags: ROS 1, and ROS 2 storage files without their folder.
BAG_SUFFIXES = (".bag", ".mcap", ".db3")
#: The labels table looked for beside the bags when ``labels`` is not given.
LABELS_FILE = "labels.csv"
#: Columns of the trials table.
TRIAL_TABLE_COLUMNS = ("bag", "trial", "t_start_s", "t_end_s")
#: Marker topic types that can cut trials.
MARKER_TYPES = ("std_msgs/msg/Bool", "std_msgs/msg/String")
_HEADER = "std_msgs/msg/Header"
_MULTIARRAY = re.compile(r"^std_msgs/(msg/)?\w+MultiArray$")
#: Units of the fields of common messages (REP 103: SI units).
_KNOWN_UNITS: dict[str, tuple[tuple[str, str], ...]] = {
    "geometry_msgs/msg/WrenchStamped": (
        ("wrench.force.", "N"),
        ("wrench.torque.", "N m"),
    ),
    "geometry_msgs/msg/Wrench": (("force.", "N"), ("torque.", "N m")),
}
_NS = 1_000_000_000


# -- bags --------------------------------------------------------------------------
@dataclass(frozen=True)
class _Bag:
    id: str
    path: Path

    def names(self) -> set[str]:
        """What a table may call this bag: its id or its file / folder name."""
        return {self.id, self.path.name}


def _is_bag(path: Path) -> bool:
    if path.is_file():
        return path.suffix in BAG_SUFFIXES
    return path.is_dir() and (path / "metadata.yaml").is_file()


def _find_bags(path: Path) -> tuple[list[_Bag], Path, bool]:
    """The bags to read, the folder beside them, and whether ``path`` was one bag."""
    if not path.exists():
        raise SourceFormatError(f"{path}: no such file or folder")
    if _is_bag(path):
        bag_id = path.stem if path.is_file() else path.name
        return [_Bag(bag_id, path)], path.parent, True
    if not path.is_dir():
        raise SourceFormatError(
            f"{path}: not a bag; expected a ROS 1 .bag file, a ROS 2 bag folder "
            "(holding metadata.yaml), a .mcap or .db3 file, or a folder of those"
        )
    bags: list[_Bag] = []
    seen: dict[str, Path] = {}
    for entry in sorted(path.iterdir()):
        if entry.name.startswith(".") or not _is_bag(entry):
            continue
        bag_id = entry.stem if entry.is_file() else entry.name
        if bag_id in seen:
            raise SourceFormatError(
                f"{entry}: bag name {bag_id!r} is also the name of {seen[bag_id]}; "
                "bag names must be unique in a folder"
            )
        seen[bag_id] = entry
        bags.append(_Bag(bag_id, entry))
    if not bags:
        raise SourceFormatError(
            f"{path}: holds no bag (no .bag, .mcap or .db3 file, no folder with a "
            "metadata.yaml)"
        )
    return bags, path, False


# -- message types ---------------------------------------------------------------------
def _msg_files(given: Sequence[str | Path]) -> list[Path]:
    files: list[Path] = []
    for item in given:
        p = Path(item)
        if p.is_dir():
            found = sorted(p.rglob("*.msg"))
            if not found:
                raise SourceFormatError(
                    f"{p}: msg_files names a folder with no .msg file"
                )
            files.extend(found)
        elif p.is_file() and p.suffix == ".msg":
            files.append(p)
        else:
            raise SourceFormatError(
                f"{p}: msg_files expects .msg files or folders of them; no such .msg file"
            )
    return files


def _typestore(msg_files: Sequence[str | Path]) -> Any:
    """The message types known besides a bag's own: ROS 2's latest, plus ``msg_files``.

    A ``.msg`` file's type is ``<package>/msg/<Name>`` from its place,
    ``<package>/msg/<Name>.msg``.
    """
    from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore

    store = get_typestore(Stores.LATEST)
    types: dict[str, Any] = {}
    for file in _msg_files(msg_files):
        if file.parent.name != "msg" or not file.parent.parent.name:
            raise SourceFormatError(
                f"{file}: cannot tell its package; place it as <package>/msg/{file.name}"
            )
        name = f"{file.parent.parent.name}/msg/{file.stem}"
        try:
            text = file.read_text(encoding="utf-8")
            types.update(get_types_from_msg(text, name))
        except (TypesysError, UnicodeDecodeError) as exc:
            raise SourceFormatError(
                f"{file}: not a readable message definition ({exc})"
            ) from exc
    if types:
        try:
            store.register(types)
        except TypesysError as exc:
            raise SourceFormatError(
                f"msg_files: the definitions do not fit together ({exc})"
            ) from exc
    return store


def _read_errors() -> tuple[type[BaseException], ...]:
    """What ``rosbags`` and its storage back ends raise for a damaged or truncated bag."""
    import sqlite3
    import struct

    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error
    from rosbags.serde import SerdeError
    from rosbags.typesys import TypesysError

    errors: list[type[BaseException]] = [
        AnyReaderError,
        Reader1Error,
        Reader2Error,
        SerdeError,
        TypesysError,
        sqlite3.Error,
        struct.error,
        EOFError,
    ]
    try:  # the sqlite3 storage reader of rosbags uses apsw where it is installed
        import apsw

        errors.append(apsw.Error)
    except ImportError:  # pragma: no cover - apsw comes with rosbags
        pass
    return tuple(errors)


# -- messages to numbers ------------------------------------------------------------
class _NotNumeric(Exception):
    def __init__(self, path: str, what: str) -> None:
        self.path, self.what = path, what


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _fields(obj: Any) -> list[str]:
    return [f.name for f in dataclasses.fields(obj) if not f.name.startswith("__")]


def _flatten(
    obj: Any, prefix: str, layout: list[tuple[str, int]], values: list[Any]
) -> None:
    """Append ``obj``'s numbers to ``values`` and their (name, count) to ``layout``."""
    msgtype = getattr(type(obj), "__msgtype__", None)
    if msgtype is not None:
        if msgtype == _HEADER:
            return
        names = ["data"] if _MULTIARRAY.match(msgtype) else _fields(obj)
        for name in names:
            _flatten(getattr(obj, name), _join(prefix, name), layout, values)
        return
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biuf":
            raise _NotNumeric(prefix, f"an array of {obj.dtype}")
        layout.append((prefix, int(obj.size)))
        values.append(obj.ravel())
        return
    if isinstance(obj, bool | int | float | np.bool_ | np.integer | np.floating):
        layout.append((prefix, -1))
        values.append(float(obj))
        return
    if isinstance(obj, list | tuple):
        if any(isinstance(item, str | bytes) for item in obj):
            raise _NotNumeric(prefix, "text")
        for i, item in enumerate(obj):
            _flatten(item, f"{prefix}_{i}", layout, values)
        return
    what = "text" if isinstance(obj, str | bytes) else type(obj).__name__
    raise _NotNumeric(prefix, what)


def _names(layout: Sequence[tuple[str, int]]) -> tuple[str, ...]:
    out: list[str] = []
    for name, count in layout:
        out.extend([name] if count < 0 else [f"{name}_{i}" for i in range(count)])
    return tuple(out)


def _select(msg: Any, path: str) -> Any:
    obj = msg
    for part in path.split("."):
        if getattr(type(obj), "__msgtype__", None) is None or part not in _fields(obj):
            raise KeyError(part)
        obj = getattr(obj, part)
    return obj


def _stamp_ns(msg: Any) -> int | None:
    header: Any = getattr(msg, "header", None)
    if getattr(type(header), "__msgtype__", None) != _HEADER:
        return None
    return int(header.stamp.sec) * _NS + int(header.stamp.nanosec)


@dataclass
class _Topic:
    """Everything read from one topic of one bag."""

    msgtype: str
    layout: list[tuple[str, int]] | None = None
    times: list[int] = field(default_factory=list)
    rows: list[np.ndarray] = field(default_factory=list)


class _Reader:
    """Reads the chosen topics of one bag into arrays, checking every message."""

    def __init__(
        self,
        bag: _Bag,
        topics: Sequence[str],
        fields: Mapping[str, Sequence[str]],
        stamp: str,
        marker: str | None,
        store: Any,
    ) -> None:
        self.bag, self.topics, self.fields = bag, topics, fields
        self.stamp, self.marker, self.store = stamp, marker, store

    def fail(self, problem: str) -> SourceFormatError:
        return SourceFormatError(f"{self.bag.path}: {problem}")

    def read(self) -> tuple[dict[str, _Topic], list[tuple[int, Any]]]:
        from rosbags.highlevel import AnyReader

        errors = _read_errors()
        data: dict[str, _Topic] = {}
        markers: list[tuple[int, Any]] = []
        count = 0
        try:
            with AnyReader([self.bag.path], default_typestore=self.store) as reader:
                conns = self._connections(reader)
                for conn, received, raw in reader.messages(connections=conns):
                    if conn.topic == self.marker:
                        msg = self._decode(
                            reader, raw, conn.msgtype, conn.topic, len(markers)
                        )
                        markers.append((int(received), msg.data))
                    else:
                        topic = data.setdefault(conn.topic, _Topic(conn.msgtype))
                        msg = self._decode(
                            reader, raw, conn.msgtype, conn.topic, len(topic.times)
                        )
                        self._add(topic, conn.topic, msg, int(received))
                    count += 1
        except SourceFormatError:
            raise
        except errors as exc:
            detail = str(exc) or type(exc).__name__
            after = f" after {count} messages" if count else ""
            raise self.fail(
                f"cannot be read{after} ({detail}); is the bag truncated or damaged?"
            ) from exc
        for name in self.topics:
            if name not in data:
                raise self.fail(f"topic {name!r} holds no message")
        return data, markers

    def _connections(self, reader: Any) -> list[Any]:
        by_topic: dict[str, list[Any]] = {}
        for conn in reader.connections:
            by_topic.setdefault(conn.topic, []).append(conn)
        wanted = [*self.topics, *([self.marker] if self.marker else [])]
        chosen: list[Any] = []
        for topic in wanted:
            if topic not in by_topic:
                have = ", ".join(sorted(by_topic)) or "none"
                raise self.fail(f"no topic {topic!r}; the bag's topics: {have}")
            types = sorted({c.msgtype for c in by_topic[topic]})
            if len(types) > 1:
                raise self.fail(
                    f"topic {topic!r} carries several message types {types}; "
                    "expected one"
                )
            if topic == self.marker and types[0] not in MARKER_TYPES:
                raise self.fail(
                    f"topic {topic!r} (trial_topic) has type {types[0]}; expected "
                    f"one of {list(MARKER_TYPES)}"
                )
            self._know(reader, types[0], topic)
            chosen.extend(by_topic[topic])
        return chosen

    def _know(self, reader: Any, msgtype: str, topic: str) -> None:
        """Make sure ``msgtype`` can be decoded; a type the bag does not define comes
        from the default store (ROS 2 types and ``msg_files``)."""
        if msgtype in reader.typestore.fielddefs:
            return
        if msgtype not in self.store.fielddefs:
            raise self.fail(
                f"topic {topic!r} has message type {msgtype}, which the bag does not "
                "define; give its .msg file with msg_files=[...]"
            )
        missing = {
            k: v
            for k, v in self.store.fielddefs.items()
            if k not in reader.typestore.fielddefs
        }
        reader.typestore.register(missing)

    def _decode(self, reader: Any, raw: bytes, msgtype: str, topic: str, k: int) -> Any:
        try:
            return reader.deserialize(raw, msgtype)
        except _read_errors() as exc:
            raise self.fail(
                f"topic {topic!r}, message {k}: cannot be decoded as {msgtype} ({exc})"
            ) from exc

    def _add(self, topic: _Topic, name: str, msg: Any, received: int) -> None:
        k = len(topic.times)
        where = f"topic {name!r}, message {k}"
        layout: list[tuple[str, int]] = []
        values: list[Any] = []
        paths = self.fields.get(name)
        try:
            if paths is None:
                _flatten(msg, "", layout, values)
            else:
                for path in paths:
                    try:
                        part = _select(msg, path)
                    except KeyError as exc:
                        raise self.fail(
                            f"{where}: no field {path!r} ({topic.msgtype} has fields "
                            f"{', '.join(_fields(msg))})"
                        ) from exc
                    _flatten(part, path, layout, values)
        except _NotNumeric as exc:
            hint = (
                f"; pick numeric fields with fields={{{name}: [...]}}"
                if paths is None
                else ""
            )
            raise self.fail(
                f"{where}: field {exc.path!r} holds {exc.what}, not numbers{hint}"
            ) from None
        if topic.layout is None:
            if not layout or not _names(layout):
                raise self.fail(f"{where}: {topic.msgtype} has no numeric field")
            topic.layout = layout
        elif layout != topic.layout:
            first, now = _names(topic.layout), _names(layout)
            raise self.fail(
                f"{where}: has {len(now)} values ({_abbrev(now)}); message 0 had "
                f"{len(first)} ({_abbrev(first)}); every message of a topic must "
                "have the same fields and array lengths"
            )
        stamp = _stamp_ns(msg) if self.stamp == "header" else None
        t = received if stamp is None else stamp
        if topic.times:
            prev = topic.times[-1]
            if t == prev:
                raise self.fail(
                    f"{where}: repeats the time of message {k - 1} ({_clock(t)}); "
                    "times must increase"
                    + (
                        " (an unset header.stamp? stamp=receive uses the recording time)"
                        if stamp is not None
                        else ""
                    )
                )
            if t < prev:
                raise self.fail(
                    f"{where}: time {_clock(t)} is before message {k - 1}'s "
                    f"({_clock(prev)}); times must increase"
                )
        topic.times.append(t)
        topic.rows.append(np.hstack(values).astype(np.float64, copy=False))


def _clock(ns: int) -> str:
    sign, ns = ("-", -ns) if ns < 0 else ("", ns)
    return f"{sign}{ns // _NS}.{ns % _NS:09d} s"  # exact: a float loses the ns


def _abbrev(names: Sequence[str], keep: int = 3) -> str:
    if len(names) <= 2 * keep:
        return ", ".join(names)
    return ", ".join([*names[:keep], "...", *names[-keep:]])


# -- trials ----------------------------------------------------------------------------
@dataclass(frozen=True)
class _Window:
    """One trial: the samples of ``bag`` with ``start <= time < end`` (ns), ``t`` from
    ``zero``."""

    trial_id: str
    bag: _Bag
    name: str | None
    start: int | None
    end: int | None
    zero: int
    where: str


def _origin(data: Mapping[str, _Topic]) -> int:
    return min(topic.times[0] for topic in data.values())


def _windows_from_table(
    file: Path, bags: Sequence[_Bag], single: bool
) -> dict[str, list[tuple[str, float, float, str]]]:
    """Bag id -> (trial name, t_start_s, t_end_s, 'file: line') of the trials table."""
    df = read_csv_file(file)
    if df.empty:
        raise SourceFormatError(f"{file}: has a header but no rows")
    cols = [str(c) for c in df.columns]
    missing = [c for c in TRIAL_TABLE_COLUMNS if c not in cols]
    if missing:
        raise SourceFormatError(
            f"{file}: no column {missing[0]!r}; a trials table has columns "
            f"{', '.join(TRIAL_TABLE_COLUMNS)}"
        )
    extra = [c for c in cols if c not in TRIAL_TABLE_COLUMNS]
    if extra:
        raise SourceFormatError(
            f"{file}: unexpected column {extra[0]!r}; a trials table has exactly "
            f"{', '.join(TRIAL_TABLE_COLUMNS)} (labels and groups go in {LABELS_FILE})"
        )
    times = numeric_block(file, df, ["t_start_s", "t_end_s"])
    ids = _bag_ids(file, df, bags, single)
    out: dict[str, list[tuple[str, float, float, str]]] = {}
    seen: dict[tuple[str, str], int] = {}
    for row in range(len(df)):
        bag_id = ids[row]
        if bag_id is None:
            continue
        name = _text(df["trial"].iloc[row])
        line = line_of(row)
        if not name:
            raise SourceFormatError(
                f"{file}: line {line}, column 'trial': missing trial name"
            )
        if (bag_id, name) in seen:
            raise SourceFormatError(
                f"{file}: line {line}: trial {name!r} of bag {bag_id!r} repeats line "
                f"{seen[(bag_id, name)]}"
            )
        seen[(bag_id, name)] = line
        start, end = (float(v) for v in times[row])
        if not end > start:
            raise SourceFormatError(
                f"{file}: line {line}: t_end_s {end:g} is not after t_start_s {start:g}"
            )
        out.setdefault(bag_id, []).append((name, start, end, f"{file}: line {line}"))
    for bag in bags:
        if bag.id not in out:
            raise SourceFormatError(f"{file}: no trial of bag {bag.id!r} ({bag.path})")
    return out


def _windows_from_markers(
    bag: _Bag, marker: str, markers: Sequence[tuple[int, Any]]
) -> list[tuple[str, int, int | None]]:
    """(trial name, start ns, end ns or None: the bag's end) cut by a marker topic.

    The marker is a state: a trial lasts while it holds the same true / non-empty
    value (a publisher repeating ``true`` at a rate makes one trial, not many) and
    ends when the value changes; a new true / non-empty value starts the next one.
    """
    windows: list[tuple[str, int, int | None]] = []
    state: Any = None
    open_at = 0
    count = 0
    for when, value in markers:
        on = bool(value) if isinstance(value, bool | np.bool_) else value != ""
        value = bool(value) if isinstance(value, bool | np.bool_) else str(value)
        if state is not None and value == state:
            continue
        if state is not None:
            name = state if isinstance(state, str) else str(count - 1)
            windows.append((name, open_at, when))
            state = None
        if on:
            state, open_at = value, when
            count += 1
    if state is not None:
        windows.append(
            (state if isinstance(state, str) else str(count - 1), open_at, None)
        )
    if not windows:
        raise SourceFormatError(
            f"{bag.path}: topic {marker!r} (trial_topic) starts no trial (no true / "
            "non-empty message)"
        )
    names = [w[0] for w in windows]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise SourceFormatError(
            f"{bag.path}: topic {marker!r} (trial_topic) starts trial {dup!r} twice; "
            "trial names must be unique within a bag"
        )
    return windows


def _text(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float | np.floating) and float(value).is_integer():
        return str(int(value))
    return str(value).strip()


def _bag_ids(
    file: Path, df: pd.DataFrame, bags: Sequence[_Bag], single: bool
) -> list[str | None]:
    """The bag id each row names (None: another bag, when one bag was imported)."""
    if "bag" not in df.columns:
        raise SourceFormatError(f"{file}: no column 'bag'")
    lookup = {name: bag.id for bag in bags for name in bag.names()}
    ids: list[str | None] = []
    for row, value in enumerate(df["bag"]):
        name = _text(value)
        if not name:
            raise SourceFormatError(
                f"{file}: line {line_of(row)}, column 'bag': missing bag name"
            )
        if name in lookup:
            ids.append(lookup[name])
        elif single:
            ids.append(None)
        else:
            known = ", ".join(sorted(b.id for b in bags))
            raise SourceFormatError(
                f"{file}: line {line_of(row)}, column 'bag': no bag {name!r} here "
                f"(bags: {known})"
            )
    return ids


# -- labels ------------------------------------------------------------------------------
def _labels(
    file: Path,
    windows: Sequence[_Window],
    bags: Sequence[_Bag],
    single: bool,
    cut: bool,
) -> tuple[pd.DataFrame, dict[str, LabelSpec], tuple[str, ...]]:
    """The trials table, label specs and groups from ``labels.csv``."""
    df = read_csv_file(file)
    df.columns = [str(c) for c in df.columns]
    keys = ["bag", "trial"] if cut else ["bag"]
    if cut and "trial" not in df.columns:
        raise SourceFormatError(
            f"{file}: no column 'trial'; bags are cut into trials, so each row names "
            "its bag and trial"
        )
    if not cut and "trial" in df.columns:
        raise SourceFormatError(
            f"{file}: column 'trial', but each bag is one trial (give trials=... or "
            "trial_topic=... to cut bags into trials)"
        )
    for reserved in ("trial_id", "t"):
        if reserved in df.columns:
            raise SourceFormatError(
                f"{file}: column {reserved!r} is slipkit's own in every dataset; "
                "rename it"
            )
    ids = _bag_ids(file, df, bags, single)
    rows: dict[str, int] = {}
    for row, bag_id in enumerate(ids):
        if bag_id is None:
            continue
        tid = bag_id if not cut else f"{bag_id}/{_text(df['trial'].iloc[row])}"
        if tid in rows:
            raise SourceFormatError(
                f"{file}: line {line_of(row)}: repeats the row of "
                f"{'trial' if cut else 'bag'} {tid!r} at line {line_of(rows[tid])}"
            )
        rows[tid] = row
    known = {w.trial_id for w in windows}
    for tid, row in rows.items():
        if tid not in known:
            raise SourceFormatError(
                f"{file}: line {line_of(row)}: no trial {tid!r} among the trials read"
            )
    for w in windows:
        if w.trial_id not in rows:
            what = (
                f"trial {w.name!r} of bag {w.bag.id!r}" if cut else f"bag {w.bag.id!r}"
            )
            raise SourceFormatError(f"{file}: no row for {what}")
    values = [c for c in df.columns if c not in keys]
    label_cols = tuple(c for c in values if c in STANDARD_LABELS)
    group_cols = tuple(c for c in values if c not in STANDARD_LABELS)
    order = [rows[w.trial_id] for w in windows]
    table = df.iloc[order][[*group_cols, *label_cols]].reset_index(drop=True)
    table.insert(0, "trial_id", [w.trial_id for w in windows])
    where = {w.trial_id: (file, line_of(rows[w.trial_id])) for w in windows}
    for col in label_cols:
        if col.endswith("_s"):
            raw = table[col]
            numbers = pd.to_numeric(raw, errors="coerce")
            bad = np.flatnonzero((numbers.isna() & raw.notna()).to_numpy())
            if len(bad):
                k = int(bad[0])
                _, line = where[str(table["trial_id"].iloc[k])]
                raise SourceFormatError(
                    f"{file}: line {line}, column {col!r}: {raw.iloc[k]!r} is not a "
                    "number of seconds (leave the cell empty for no slip)"
                )
            table[col] = numbers.astype(np.float64)
    labels = {col: _label_spec(col, table, None, None, where) for col in label_cols}
    if "slip_onset_s" in labels:
        labels["slip_onset_s"] = LabelSpec(
            "slip_onset_s",
            unit="s",
            description=(
                f"true slip onset, s from the trial start, from {file.name}; NaN (an "
                "empty cell): no slip"
            ),
        )
    return table, labels, group_cols


# -- the importer ------------------------------------------------------------------------
def _stream_names(topics: Sequence[str] | Mapping[str, str] | None) -> dict[str, str]:
    if topics is None:
        topics = []
    if isinstance(topics, str):
        topics = [topics]
    if isinstance(topics, Mapping):
        pairs = [(str(k), str(v)) for k, v in topics.items()]
    else:
        pairs = [(str(t), str(t).strip("/").replace("/", "_")) for t in topics]
    if not pairs:
        raise SourceFormatError(
            "topics is empty; name the topics that make the streams, e.g. "
            "topics=[/biotac/electrodes] or topics={/biotac/electrodes: electrodes}"
        )
    out: dict[str, str] = {}
    for topic, stream in pairs:
        if not stream or "/" in stream:
            raise SourceFormatError(
                f"topics: stream name {stream!r} of topic {topic!r} must be non-empty "
                "and hold no '/'"
            )
        if stream in out.values():
            raise SourceFormatError(f"topics: two topics make stream {stream!r}")
        out[topic] = stream
    return out


def _units(
    units: Mapping[str, str] | str | None,
    stream: str,
    msgtype: str,
    channels: Sequence[str],
) -> dict[str, str]:
    if isinstance(units, str):
        return dict.fromkeys(channels, units)
    if units is not None and stream in units:
        return dict.fromkeys(channels, str(units[stream]))
    known = _KNOWN_UNITS.get(msgtype, ())
    out = {}
    for ch in channels:
        out[ch] = next((u for prefix, u in known if ch.startswith(prefix)), "unknown")
    return out


def read_rosbag(
    path: Path | str,
    *,
    topics: Sequence[str] | Mapping[str, str] | None,
    sensor: str = "generic",
    fields: Mapping[str, Sequence[str]] | None = None,
    units: Mapping[str, str] | str | None = None,
    stamp: str = "header",
    labels: Path | str | None = None,
    trials: Path | str | None = None,
    trial_topic: str | None = None,
    msg_files: Sequence[str | Path] = (),
) -> Dataset:
    """Read ROS bags into a dataset: one sampled stream per topic.

    Parameters
    ----------
    path : path-like
        One bag (a ROS 1 ``.bag`` file, a ROS 2 bag folder holding
        ``metadata.yaml``, or a bare ``.mcap`` / ``.db3`` file) or a folder of them
        (read in sorted order). A bag's id is its file stem or folder name.
    topics : sequence of str, or mapping of str to str
        The topics that make the streams, each one stream; a list names each stream
        after its topic (``/biotac/electrodes`` -> ``biotac_electrodes``), a mapping
        gives ``{topic: stream}``.
    sensor : str
        Sensor family recorded in the dataset.
    fields : mapping of str to sequence of str, optional
        ``{topic: [field path, ...]}``: only these fields (and everything under
        them) become channels. Default: every field; a field holding text is then
        an error naming it, so give ``fields`` for such messages.
    units : str or mapping of str to str, optional
        One unit for every channel, or ``{stream: unit}``. Default: ``N`` / ``N m``
        for the force / torque of a ``Wrench(Stamped)``, else ``unknown``.
    stamp : {"header", "receive"}
        ``header``: a sample's time is its ``header.stamp`` when the message has a
        header, else the time the bag recorded it; ``receive``: always the latter.
    labels : path-like, optional
        The labels table; default ``labels.csv`` beside the bags, when present. Column
        ``bag`` (and ``trial`` when bags are cut), then ``slip_onset_s`` (s from the
        trial start; an empty cell is NaN: no slip), ``reference_onset_s``,
        ``slip_class`` as labels, and any other column (``object``) as a group.
        Every trial needs one row.
    trials : path-like, optional
        Cut bags into trials by a table with columns ``bag, trial, t_start_s,
        t_end_s`` (seconds from the bag's first sample; a trial holds the samples
        with ``t_start_s <= t < t_end_s`` and its ``t`` starts at ``t_start_s``).
    trial_topic : str, optional
        Cut bags into trials by a ``std_msgs/Bool`` topic (true starts a trial,
        named 0, 1, ...; false ends it) or ``std_msgs/String`` topic (a text starts
        a trial named by it, an empty text ends it). Marker times are the recording
        times, so the streams' stamps must be on the same clock.
    msg_files : sequence of path-like
        ``.msg`` files (or folders of them), each at ``<package>/msg/<Name>.msg``,
        defining message types that a bag does not carry itself.

    Returns
    -------
    Dataset
        Trial ids ``<bag>`` (one trial per bag) or ``<bag>/<trial>``.

    Raises
    ------
    SourceFormatError
        One line naming the bag (and topic and message, 0-based) or table line at
        fault: a missing topic, a non-numeric field, a time that repeats or goes
        back, a message whose fields differ from the topic's first, a truncated or
        damaged bag, a trial without samples of a stream, a bad table row.
    """
    path = Path(path)
    try:
        import rosbags  # noqa: F401  (the bag reader; imported here only)
    except ImportError:  # pragma: no cover - a train install has it
        raise SlipkitError(
            "reading ROS bags needs rosbags: pip install 'slipkit[train]'"
        ) from None
    if stamp not in ("header", "receive"):
        raise SourceFormatError(f"stamp={stamp!r}: expected 'header' or 'receive'")
    if trials is not None and trial_topic is not None:
        raise SourceFormatError(
            "trials and trial_topic are both given; cut bags one way"
        )
    streams = _stream_names(topics)
    if trial_topic is not None and trial_topic in streams:
        raise SourceFormatError(
            f"trial_topic {trial_topic!r} is also one of the topics; a marker topic "
            "is not a stream"
        )
    fields = {str(k): [str(p) for p in v] for k, v in (fields or {}).items()}
    stray = sorted(set(fields) - set(streams))
    if stray:
        raise SourceFormatError(
            f"fields names topics {stray} that are not among topics {list(streams)}"
        )
    bags, folder, single = _find_bags(path)
    label_file = None if labels is None else Path(labels)
    if label_file is not None and not label_file.is_file():
        raise SourceFormatError(f"{label_file}: no such labels file (labels=...)")
    if label_file is None and (folder / LABELS_FILE).is_file():
        label_file = folder / LABELS_FILE
    table_windows = None
    if trials is not None:
        trials_file = Path(trials)
        if not trials_file.is_file():
            raise SourceFormatError(f"{trials_file}: no such trials table (trials=...)")
        table_windows = _windows_from_table(trials_file, bags, single)
    store = _typestore(msg_files)

    windows: list[_Window] = []
    read: dict[str, dict[str, _Topic]] = {}
    for bag in bags:
        data, markers = _Reader(
            bag, list(streams), fields, stamp, trial_topic, store
        ).read()
        read[bag.id] = data
        zero = _origin(data)
        if table_windows is not None:
            for name, t0, t1, where in table_windows[bag.id]:
                start, end = zero + round(t0 * _NS), zero + round(t1 * _NS)
                windows.append(
                    _Window(f"{bag.id}/{name}", bag, name, start, end, start, where)
                )
        elif trial_topic is not None:
            for name, mark, until in _windows_from_markers(bag, trial_topic, markers):
                windows.append(
                    _Window(
                        f"{bag.id}/{name}",
                        bag,
                        name,
                        mark,
                        until,
                        mark,
                        f"{bag.path}: topic {trial_topic!r}",
                    )
                )
        else:
            windows.append(_Window(bag.id, bag, None, None, None, zero, str(bag.path)))
    tables, specs = _stream_tables(streams, bags, read, windows, units)

    cut = trials is not None or trial_topic is not None
    if label_file is not None:
        trial_table, label_specs, groups = _labels(
            label_file, windows, bags, single, cut
        )
    else:
        trial_table = pd.DataFrame({"trial_id": [w.trial_id for w in windows]})
        label_specs, groups = {}, ()
    dataset = Dataset(
        sensor=sensor,
        streams=specs,
        trials=trial_table,
        tables=tables,
        labels=label_specs,
        groups=groups,
        provenance={
            "source": str(path),
            "importer": "slipkit.data.importers.rosbag.read_rosbag",
            "bags": [b.path.name for b in bags],
            "topics": dict(streams),
            "message_types": {
                topic: sorted({read[b.id][topic].msgtype for b in bags})
                for topic in streams
            },
            "assumptions": [
                "t: header.stamp where a message has a header, else the recording time"
                if stamp == "header"
                else "t: the recording time of each message",
                "rate_hz of each stream: 1 / median time step over all its trials",
            ],
            "options": {
                "fields": fields,
                "stamp": stamp,
                "labels": None if label_file is None else str(label_file),
                "trials": None if trials is None else str(trials),
                "trial_topic": trial_topic,
                "msg_files": [str(p) for p in msg_files],
            },
        },
        name=path.stem if path.is_file() else path.resolve().name,
    )
    return dataset


def _stream_tables(
    streams: Mapping[str, str],
    bags: Sequence[_Bag],
    read: Mapping[str, Mapping[str, _Topic]],
    windows: Sequence[_Window],
    units: Mapping[str, str] | str | None,
) -> tuple[dict[str, pd.DataFrame], dict[str, StreamSpec]]:
    """Each stream's long table (the samples of each trial window) and spec."""
    tables: dict[str, pd.DataFrame] = {}
    specs: dict[str, StreamSpec] = {}
    for topic, stream in streams.items():
        first = bags[0]
        ref = read[first.id][topic]
        assert ref.layout is not None
        channels = _names(ref.layout)
        arrays: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for bag in bags:
            got = read[bag.id][topic]
            assert got.layout is not None
            if got.msgtype != ref.msgtype:
                raise SourceFormatError(
                    f"{bag.path}: topic {topic!r} has type {got.msgtype}; it is "
                    f"{ref.msgtype} in {first.path}"
                )
            if _names(got.layout) != channels:
                now = _names(got.layout)
                raise SourceFormatError(
                    f"{bag.path}: topic {topic!r} has {len(now)} channels "
                    f"({_abbrev(now)}); {first.path} has {len(channels)} "
                    f"({_abbrev(channels)}); every bag must agree"
                )
            arrays[bag.id] = (
                np.asarray(got.times, dtype=np.int64),
                np.vstack(got.rows),
            )
        parts: list[pd.DataFrame] = []
        diffs: list[np.ndarray] = []
        for w in windows:
            times, values = arrays[w.bag.id]
            lo = 0 if w.start is None else int(np.searchsorted(times, w.start, "left"))
            hi = (
                len(times)
                if w.end is None
                else int(np.searchsorted(times, w.end, "left"))
            )
            if hi <= lo:
                raise SourceFormatError(
                    f"{w.where}: trial {w.trial_id!r} holds no message of topic "
                    f"{topic!r}"
                )
            t = (times[lo:hi] - w.zero).astype(np.float64) / _NS
            part = pd.DataFrame(values[lo:hi], columns=list(channels))
            part.insert(0, "t", t)
            part.insert(0, "trial_id", w.trial_id)
            parts.append(part)
            diffs.append(np.diff(t))
        dt = np.concatenate(diffs)
        if dt.size == 0:
            raise SourceFormatError(
                f"{first.path}: topic {topic!r}: every trial holds one message; "
                "cannot estimate a sample rate"
            )
        rate = float(round(1.0 / float(np.median(dt)), 6))
        specs[stream] = StreamSpec(
            stream,
            channels,
            _units(units, stream, ref.msgtype, channels),
            rate_hz=rate,
            description=f"ROS topic {topic} ({ref.msgtype})",
        )
        tables[stream] = pd.concat(parts, ignore_index=True)
    return tables, specs
