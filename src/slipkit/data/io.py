"""Read and write dataset folders (``manifest.json`` + Parquet), checked and atomic.

Layout (documented for users in ``docs/dataset-format.md``)::

    <dataset>/manifest.json
    <dataset>/trials.parquet          one row per trial
    <dataset>/streams/<name>.parquet  long table: trial_id, t (s), channels
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from slipkit import __version__
from slipkit._files import atomic_dir, recover_leftovers, sha256_file
from slipkit.data._manifest import (
    MAX_MANIFEST_BYTES,
    parse_manifest_bytes,
    validate_manifest,
)
from slipkit.data.dataset import FORMAT, SCHEMA_VERSION, Dataset, LabelSpec, StreamSpec
from slipkit.errors import DatasetError

MANIFEST = "manifest.json"
TRIALS = "trials.parquet"
#: Values (rows x columns) per Parquet row group in the files :func:`save_dataset`
#: writes: 8 MB of float64, whatever the channel count.
ROW_GROUP_VALUES = 1_048_576
#: Stream values (rows x columns, summed over streams) a chunk of
#: :func:`iter_dataset_chunks` aims at: 8 MB of float64.
CHUNK_VALUES = 1_048_576


def stream_file(name: str) -> str:
    """Relative path of a stream's table inside a dataset folder."""
    return f"streams/{name}.parquet"


def _write_parquet(df: pd.DataFrame, path: Path) -> None:
    # zstd keeps float channels small; the writer is deterministic for a given
    # pyarrow version, so one seed gives byte-identical files. Row groups of
    # about ROW_GROUP_VALUES values let a reader take a few trials at a time
    # (iter_dataset_chunks) instead of decompressing a whole stream.
    # At most 65536 rows: a narrow table's trial_id strings would otherwise outweigh
    # its values.
    rows = min(65_536, max(1024, ROW_GROUP_VALUES // max(1, len(df.columns))))
    df.to_parquet(
        path,
        index=False,
        compression="zstd",
        engine="pyarrow",
        row_group_size=rows,
    )


def save_dataset(
    dataset: Dataset, path: Path | str, *, overwrite: bool = False
) -> Path:
    """Write ``dataset`` to the folder ``path`` atomically and return the path.

    Everything is written into a temporary sibling folder, checksummed, and
    renamed into place last: a crash leaves either the old folder or the new one,
    never half of either.
    """
    path = Path(path)
    with atomic_dir(path, overwrite=overwrite, kind="dataset") as tmp:
        (tmp / "streams").mkdir()
        files: dict[str, str] = {}
        _write_parquet(dataset.trials, tmp / TRIALS)
        files[TRIALS] = sha256_file(tmp / TRIALS)
        for name, table in sorted(dataset.tables.items()):
            rel = stream_file(name)
            _write_parquet(table, tmp / rel)
            files[rel] = sha256_file(tmp / rel)
        manifest = {
            "format": FORMAT,
            "schema_version": SCHEMA_VERSION,
            "name": dataset.name,
            "sensor": dataset.sensor,
            "n_trials": len(dataset),
            "streams": {
                s: spec.to_json() for s, spec in sorted(dataset.streams.items())
            },
            "labels": {k: v.to_json() for k, v in sorted(dataset.labels.items())},
            "groups": list(dataset.groups),
            "provenance": _jsonable(dataset.provenance),
            "written_by": f"slipkit {__version__}",
            "files": files,
        }
        (tmp / MANIFEST).write_text(
            json.dumps(manifest, indent=2, sort_keys=False) + "\n", encoding="utf-8"
        )
    return path


def _jsonable(obj: Any) -> Any:
    """Provenance may hold numpy scalars or OmegaConf containers: make it plain JSON."""
    return json.loads(json.dumps(obj, default=_default))


def _default(obj: Any) -> Any:
    if hasattr(obj, "item"):
        return obj.item()
    if hasattr(obj, "tolist"):
        return obj.tolist()
    try:
        from omegaconf import OmegaConf

        if OmegaConf.is_config(obj):
            return OmegaConf.to_container(obj, resolve=True)
    except ImportError:  # pragma: no cover - omegaconf ships with hydra-core
        pass
    return str(obj)


def read_manifest(path: Path | str) -> dict[str, Any]:
    """Read ``manifest.json`` of a dataset folder and check it against its schema.

    The file is read as bounded JSON (at most ``MAX_MANIFEST_BYTES``, nesting at most
    ``MAX_DEPTH``, no key twice in one object) and validated against
    ``slipkit/data/schema/dataset-manifest.schema.json`` (see
    ``docs/dataset-format.md``): field types, ranges and required fields.

    Raises
    ------
    DatasetError
        Naming ``manifest.json`` and the field path at fault, e.g.
        ``streams.force.rate_hz: expected a positive number (Hz, at most 1e9) for
        a sampled stream, got true``.
    """
    path = Path(path)
    mpath = path / MANIFEST
    if not path.is_dir():
        raise DatasetError(
            str(path), "not a folder; a dataset is a folder holding manifest.json"
        )
    if not mpath.is_file():
        raise DatasetError(str(mpath), "missing; not a slipkit dataset folder")
    _check_inside(path, MANIFEST)
    size = mpath.stat().st_size
    if size > MAX_MANIFEST_BYTES:
        raise DatasetError(
            str(mpath),
            f"is {size} bytes; a manifest is at most {MAX_MANIFEST_BYTES} bytes",
        )
    with open(mpath, "rb") as fh:
        # Read one byte past the cap so that an over-long file is refused without
        # reading all of it (a manifest could be swapped for a multi-GB file).
        data = fh.read(MAX_MANIFEST_BYTES + 1)
    manifest = parse_manifest_bytes(data, str(mpath))
    if not isinstance(manifest, dict):
        raise DatasetError(str(mpath), "expected a JSON object at the top level")
    if manifest.get("format") != FORMAT:
        raise DatasetError(
            str(mpath),
            f"field 'format' is {manifest.get('format')!r}; expected {FORMAT!r}",
        )
    version = manifest.get("schema_version")
    if (
        isinstance(version, int)
        and not isinstance(version, bool)
        and version > SCHEMA_VERSION
    ):
        # Before the schema: a newer version may lay out the other fields differently.
        raise DatasetError(
            str(mpath),
            f"field 'schema_version' is {version}, newer than this slipkit reads ({SCHEMA_VERSION}); upgrade slipkit",
        )
    validate_manifest(manifest, str(mpath))
    return manifest


def _check_inside(root: Path, rel: str) -> Path:
    """``root / rel``, refused unless it resolves inside ``root`` (``..``, an absolute
    path or a symlink pointing out of the dataset folder)."""
    target = root / rel
    base = root.resolve()
    resolved = target.resolve()
    if not resolved.is_relative_to(base):
        raise DatasetError(
            str(target),
            f"resolves to {resolved}, outside the dataset folder {base}; every file "
            "of a dataset must lie inside its folder (no '..', absolute path, or "
            "symlink pointing out)",
        )
    return target


def _read_parquet(path: Path, rel: str) -> pd.DataFrame:
    try:
        return pd.read_parquet(path / rel, engine="pyarrow")
    except Exception as exc:  # pyarrow raises several types for corrupt files
        raise DatasetError(
            str(path / rel),
            f"could not be read as Parquet ({type(exc).__name__}: {exc})",
        ) from exc


def load_dataset(path: Path | str, *, verify: bool = True) -> Dataset:
    """Load a dataset folder written by :func:`save_dataset` (or by hand, see the docs).

    Parameters
    ----------
    path : path-like
        The dataset folder.
    verify : bool
        Check the sha256 of every file against the manifest (default). Every other
        check (schema version, columns, dtypes, time order) always runs.

    Raises
    ------
    DatasetError
        Naming the file and the field or column at fault, and what was expected.
    """
    path = Path(path)
    manifest, specs, labels, trials = _open_folder(path, verify=verify)
    tables = {s: _read_parquet(path, stream_file(s)) for s in specs}
    dataset = Dataset(
        sensor=manifest["sensor"],
        streams=specs,
        trials=trials,
        tables=tables,
        labels=labels,
        groups=manifest["groups"],
        provenance=manifest["provenance"],
        name=str(manifest.get("name", "")) or path.name,
        sources={
            "trials": str(path / TRIALS),
            **{s: str(path / stream_file(s)) for s in specs},
        },
    )
    for s, table in dataset.tables.items():
        _check_channels_hold_data(table, dataset.streams[s], path / stream_file(s))
    return dataset


def _open_folder(
    path: Path, *, verify: bool
) -> tuple[dict[str, Any], dict[str, StreamSpec], dict[str, LabelSpec], pd.DataFrame]:
    """The checks every reader of a dataset folder runs before any stream is read:
    manifest, listed files (inside the folder, present, sha256 if ``verify``), the
    trials table. Returns the manifest, stream specs, label specs and trials table."""
    recover_leftovers(path)  # an interrupted overwrite: restore or report it
    manifest = read_manifest(path)
    mpath = str(path / MANIFEST)
    files: Mapping[str, str] = manifest["files"]
    specs = {
        name: StreamSpec.from_json(name, entry, mpath)
        for name, entry in manifest["streams"].items()
    }
    expected = {TRIALS, *(stream_file(s) for s in specs)}
    unlisted = sorted(expected - set(files))
    if unlisted:
        raise DatasetError(mpath, f"field 'files' does not list {unlisted}")
    for rel in files:
        _check_inside(path, rel)
    on_disk = (
        {p.relative_to(path).as_posix() for p in (path / "streams").glob("*.parquet")}
        if (path / "streams").is_dir()
        else set()
    )
    stray = sorted(on_disk - set(files))
    if stray:
        raise DatasetError(
            str(path / stray[0]),
            "is not listed in manifest.json 'files' (stray or renamed stream)",
        )
    for rel, digest in files.items():
        fpath = path / rel
        if not fpath.is_file():
            raise DatasetError(str(fpath), "listed in manifest.json but missing")
        if verify:
            actual = sha256_file(fpath)
            if actual != digest:
                raise DatasetError(
                    str(fpath),
                    f"sha256 mismatch: manifest says {digest[:12]}..., file has {actual[:12]}... (modified or truncated)",
                )
    trials = _read_parquet(path, TRIALS)
    if len(trials) == 0:
        raise DatasetError(
            str(path / TRIALS), "has no rows; a dataset holds at least one trial"
        )
    n_trials = manifest.get("n_trials", len(trials))
    if n_trials != len(trials):
        raise DatasetError(
            mpath,
            f"field 'n_trials' is {n_trials}, but {TRIALS} has {len(trials)} rows",
        )
    labels = {k: LabelSpec.from_json(k, v) for k, v in manifest["labels"].items()}
    return manifest, specs, labels, trials


def _parquet_error(file: Path, exc: Exception) -> DatasetError:
    return DatasetError(
        str(file), f"could not be read as Parquet ({type(exc).__name__}: {exc})"
    )


def _scan_trial_rows(
    pf: pq.ParquetFile, file: Path, spec: StreamSpec
) -> tuple[dict[str, int], dict[str, list[int]]]:
    """One pass over a stream's ``trial_id`` column, a row group at a time: rows per
    trial and the row groups holding each trial. Refuses a trial whose rows are not
    contiguous in the whole file (the check :class:`Dataset` makes per table)."""
    expected = ["trial_id", "t", *spec.channels]
    names = pf.schema_arrow.names
    missing = [c for c in expected if c not in names]
    if missing:
        raise DatasetError(
            str(file), f"missing columns {missing}; expected columns {expected}"
        )
    rows: dict[str, int] = {}
    where: dict[str, list[int]] = {}
    last: str | None = None
    for rg in range(pf.num_row_groups):
        try:
            col = pf.read_row_group(rg, columns=["trial_id"]).column(0)
            # dictionary codes: 4 bytes a row instead of a Python string a row
            coded = pc.dictionary_encode(pc.cast(col, pa.string())).combine_chunks()
        except Exception as exc:  # pyarrow raises several types for corrupt files
            raise _parquet_error(file, exc) from exc
        codes = coded.indices.to_numpy(zero_copy_only=False)
        if not len(codes):
            continue
        names = np.asarray(coded.dictionary.to_pylist(), dtype=object)
        starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
        lengths = np.diff(np.r_[starts, len(codes)])
        for tid, n in zip(names[codes[starts]], lengths, strict=True):
            if tid != last and tid in rows:
                raise DatasetError(
                    str(file),
                    "rows of one trial are not contiguous; expected rows grouped by 'trial_id'",
                )
            last = tid
            rows[tid] = rows.get(tid, 0) + int(n)
            groups = where.setdefault(tid, [])
            if not groups or groups[-1] != rg:
                groups.append(rg)
    return rows, where


def iter_dataset_chunks(
    path: Path | str, *, verify: bool = True, max_values: int = CHUNK_VALUES
) -> Iterator[Dataset]:
    """The dataset folder as consecutive :class:`Dataset` chunks of whole trials.

    Runs every check of :func:`load_dataset` (the manifest, files and trials table
    first; each chunk through :class:`Dataset`; trial ids, contiguity and channels
    that never hold a number over the whole file), but holds only about
    ``max_values`` stream values at a time: each chunk reads only the Parquet row
    groups of its trials (about :data:`ROW_GROUP_VALUES` values each in files written
    by :func:`save_dataset`; a file written as one row group is read whole per chunk).
    For a task that needs one trial at a time (``slipkit info``, summaries).

    Parameters
    ----------
    path : path-like
        The dataset folder.
    verify : bool
        Check every file's sha256 against the manifest first.
    max_values : int
        Stream values (rows x columns, summed over streams) a chunk aims at; a chunk
        holds at least one trial, so one longer trial makes a larger chunk.

    Yields
    ------
    Dataset
        Trials in the trials table's order, each trial in exactly one chunk.

    Raises
    ------
    DatasetError
        As :func:`load_dataset`: naming the file and the field or column at fault.
    """
    path = Path(path)
    manifest, specs, labels, trials = _open_folder(path, verify=verify)
    trials = trials.reset_index(drop=True)
    ids = trials["trial_id"].astype(str)
    files = {s: path / stream_file(s) for s in specs}
    readers: dict[str, pq.ParquetFile] = {}
    rows: dict[str, dict[str, int]] = {}
    where: dict[str, dict[str, list[int]]] = {}
    for s, file in files.items():
        try:
            readers[s] = pq.ParquetFile(file)
        except Exception as exc:  # pyarrow raises several types for corrupt files
            raise _parquet_error(file, exc) from exc
        rows[s], where[s] = _scan_trial_rows(readers[s], file, specs[s])
        unknown = set(rows[s]) - set(ids)
        if unknown:
            raise DatasetError(
                str(file),
                f"column 'trial_id' names trials not in trials.parquet: {sorted(unknown)[:5]}",
            )
    width = {s: 2 + len(spec.channels) for s, spec in specs.items()}  # + trial_id, t
    finite = {s: dict.fromkeys(specs[s].channels, False) for s in specs}
    total = dict.fromkeys(specs, 0)
    common = {
        "sensor": manifest["sensor"],
        "streams": specs,
        "labels": labels,
        "groups": manifest["groups"],
        "provenance": manifest["provenance"],
        "name": str(manifest.get("name", "")) or path.name,
        "sources": {
            "trials": str(path / TRIALS),
            **{s: str(f) for s, f in files.items()},
        },
    }

    def chunk(first: int, stop: int) -> Dataset:
        keep = set(ids.iloc[first:stop])
        tables = {}
        for s, pf in readers.items():
            rgs = sorted({rg for tid in keep for rg in where[s].get(tid, ())})
            try:
                table = (
                    pf.read_row_groups(rgs) if rgs else pf.schema_arrow.empty_table()
                )
                # keep the chunk's rows in Arrow, before pandas makes a string per row
                mask = pc.is_in(
                    pc.cast(table["trial_id"], pa.string()),
                    value_set=pa.array(sorted(keep), pa.string()),
                )
                tables[s] = table.filter(mask).to_pandas()
            except Exception as exc:  # pyarrow raises several types for corrupt files
                raise _parquet_error(files[s], exc) from exc
        part = Dataset(trials=trials.iloc[first:stop], tables=tables, **common)
        for s, table in part.tables.items():
            total[s] += len(table)
            for col, seen in finite[s].items():
                if not seen:
                    values = table[col].to_numpy(dtype=np.float64, na_value=np.nan)
                    finite[s][col] = bool(np.isfinite(values).any())
        return part

    first, n = 0, 0
    for i, tid in enumerate(ids):
        n += sum(r.get(tid, 0) * width[s] for s, r in rows.items())
        if n >= max_values:
            yield chunk(first, i + 1)
            first, n = i + 1, 0
    if first < len(ids):
        yield chunk(first, len(ids))
    for s, seen in finite.items():
        empty = [c for c, ok in seen.items() if not ok]
        if total[s] and empty:
            raise DatasetError(
                str(files[s]),
                f"column '{empty[0]}' has no finite value in its {total[s]} rows (all "
                "NaN or infinite); a channel must hold data",
            )


def _check_channels_hold_data(
    table: pd.DataFrame, spec: StreamSpec, file: Path
) -> None:
    """Refuse a channel with no finite value in a non-empty table (e.g. all NaN).

    Only the whole stored dataset is checked: a subset (one trial of a TacTip
    recording whose pin is lost throughout) may legitimately hold an all-NaN
    channel, but a dataset where a channel never holds a number carries no data
    there and would train on NaN or on nothing.
    """
    if len(table) == 0:
        return
    for col in spec.channels:
        values = table[col].to_numpy(dtype=np.float64, na_value=np.nan)
        if not np.isfinite(values).any():
            raise DatasetError(
                str(file),
                f"column '{col}' has no finite value in its {len(table)} rows (all "
                "NaN or infinite); a channel must hold data",
            )
