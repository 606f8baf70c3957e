"""Read and write dataset folders (``manifest.json`` + Parquet), checked and atomic.

Layout (documented for users in ``docs/dataset-format.md``)::

    <dataset>/manifest.json
    <dataset>/trials.parquet          one row per trial
    <dataset>/streams/<name>.parquet  long table: trial_id, t (s), channels
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from slipkit import __version__
from slipkit._files import atomic_dir, recover_leftovers, sha256_file
from slipkit.data.dataset import FORMAT, SCHEMA_VERSION, Dataset, LabelSpec, StreamSpec
from slipkit.errors import DatasetError

MANIFEST = "manifest.json"
TRIALS = "trials.parquet"

_REQUIRED: dict[str, type | tuple[type, ...]] = {
    "format": str,
    "schema_version": int,
    "sensor": str,
    "streams": dict,
    "labels": dict,
    "groups": list,
    "provenance": dict,
    "files": dict,
}


def stream_file(name: str) -> str:
    """Relative path of a stream's table inside a dataset folder."""
    return f"streams/{name}.parquet"


def _write_parquet(df: pd.DataFrame, path: Path) -> None:
    # zstd keeps float channels small; the writer is deterministic for a given
    # pyarrow version, so one seed gives byte-identical files.
    df.to_parquet(path, index=False, compression="zstd", engine="pyarrow")


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
    """Read and check ``manifest.json`` of a dataset folder (fields and types only)."""
    path = Path(path)
    mpath = path / MANIFEST
    if not path.is_dir():
        raise DatasetError(
            str(path), "not a folder; a dataset is a folder holding manifest.json"
        )
    if not mpath.is_file():
        raise DatasetError(str(mpath), "missing; not a slipkit dataset folder")
    try:
        manifest = json.loads(mpath.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DatasetError(str(mpath), f"is not valid JSON ({exc})") from exc
    if not isinstance(manifest, dict):
        raise DatasetError(str(mpath), "expected a JSON object at the top level")
    if manifest.get("format") != FORMAT:
        raise DatasetError(
            str(mpath),
            f"field 'format' is {manifest.get('format')!r}; expected {FORMAT!r}",
        )
    for key, typ in _REQUIRED.items():
        if key not in manifest:
            raise DatasetError(str(mpath), f"missing field '{key}'")
        if not isinstance(manifest[key], typ) or (
            typ is int and isinstance(manifest[key], bool)
        ):
            raise DatasetError(
                str(mpath),
                f"field '{key}' is {type(manifest[key]).__name__}; expected {getattr(typ, '__name__', typ)}",
            )
    version = manifest["schema_version"]
    if version > SCHEMA_VERSION:
        raise DatasetError(
            str(mpath),
            f"field 'schema_version' is {version}, newer than this slipkit reads ({SCHEMA_VERSION}); upgrade slipkit",
        )
    if version < 1:
        raise DatasetError(
            str(mpath),
            f"field 'schema_version' is {version}; expected 1..{SCHEMA_VERSION}",
        )
    return manifest


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
    tables = {s: _read_parquet(path, stream_file(s)) for s in specs}
    labels = {k: LabelSpec.from_json(k, v) for k, v in manifest["labels"].items()}
    return Dataset(
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
