"""A slipkit dataset as a LeRobot dataset (layout v3.0), and read back.

LeRobot (Hugging Face's robot-learning datasets) keeps one frame rate per dataset,
so one sampled stream is written: each trial becomes an episode, each sample a
frame whose feature ``observation.<stream>`` holds the stream's channels in order::

    <out>/meta/info.json                        codebase_version "v3.0", fps, features
    <out>/meta/stats.json                       min, max, mean, std, count, q01..q99
    <out>/meta/tasks.parquet                    the one task (index: its text)
    <out>/meta/episodes/chunk-000/file-000.parquet  one row per episode (+ slipkit/<column>)
    <out>/data/chunk-000/file-000.parquet       episode_index, frame_index, index,
                                                timestamp, task_index, the feature
    <out>/meta/slipkit.json                     what slipkit wrote (stream, rate, units,
                                                labels) so :func:`read_lerobot` can
                                                rebuild the dataset

Rules (``docs/dataset-format.md``): ``fps`` is the stream's ``rate_hz`` rounded to a
whole number (LeRobot's fps is an integer; the exact rate is in ``slipkit.json``);
``timestamp`` is the recorded ``t`` (s from the trial start) as float32, as LeRobot
stores it, not a grid made from the fps; channel values stay float64; the trials
table's columns (labels, groups) go into the episodes table as ``slipkit/<column>``
beside ``slipkit/trial_id``. Written by hand with pyarrow: the LeRobot package itself
needs torch and writes frame by frame through an in-memory buffer; the layout is a
handful of Parquet and JSON files.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from slipkit import __version__
from slipkit._files import LEROBOT_FORMAT, atomic_dir, check_out_path
from slipkit.data.dataset import Dataset, LabelSpec, StreamSpec
from slipkit.data.io import iter_dataset_chunks, read_manifest
from slipkit.errors import DatasetError, SlipkitError

__all__ = [
    "CODEBASE_VERSION",
    "MARKER",
    "MARKER_FORMAT",
    "read_lerobot",
    "write_lerobot",
]

CODEBASE_VERSION = "v3.0"
MARKER = "meta/slipkit.json"
MARKER_FORMAT = LEROBOT_FORMAT
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
#: LeRobot's defaults: files per chunk folder, and the size a data file grows to.
CHUNKS_SIZE = 1000
DATA_FILE_MB = 100
VIDEO_FILE_MB = 200
QUANTILES = {"q01": 0.01, "q10": 0.10, "q50": 0.50, "q90": 0.90, "q99": 0.99}
INDEX_FEATURES = ("frame_index", "episode_index", "index", "task_index")
#: Every LeRobot frame has these besides the data features.
DEFAULT_FEATURES: dict[str, dict[str, Any]] = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    **{k: {"dtype": "int64", "shape": [1], "names": None} for k in INDEX_FEATURES},
}


def _pick_stream(manifest: Mapping[str, Any], stream: str | None, where: str) -> str:
    streams = manifest["streams"]
    sampled = {s: e for s, e in streams.items() if e["kind"] == "sampled"}
    listing = ", ".join(f"{s} ({e['rate_hz']:g} Hz)" for s, e in sampled.items())
    if stream is None:
        if len(sampled) == 1:
            return next(iter(sampled))
        if not sampled:
            kinds = ", ".join(f"{s} ({e['kind']})" for s, e in streams.items())
            raise SlipkitError(
                f"{where}: has no sampled stream (only "
                f"{kinds}); a "
                "LeRobot dataset needs a frame rate"
            )
        raise SlipkitError(
            f"{where}: has {len(sampled)} sampled streams ({listing}); a LeRobot "
            "dataset has one fps, so pick one with stream=<name>"
        )
    if stream not in streams:
        raise SlipkitError(
            f"stream={stream}: no such stream in {where}; streams: {', '.join(streams)}"
        )
    if stream not in sampled:
        raise SlipkitError(
            f"stream={stream}: is a {streams[stream]['kind']} stream without a rate; a "
            f"LeRobot dataset needs a sampled stream ({listing or 'none here'})"
        )
    return stream


def _stats(values: np.ndarray) -> dict[str, np.ndarray]:
    """LeRobot's statistics of one feature over frames (rows), per dimension; values
    that are not finite (a dropped sample) are left out."""
    finite = np.where(np.isfinite(values), values, np.nan).astype(np.float64)
    with warnings.catch_warnings():  # a channel without a finite value: NaN, no warning
        warnings.simplefilter("ignore", RuntimeWarning)
        out = {
            "min": np.nanmin(finite, axis=0),
            "max": np.nanmax(finite, axis=0),
            "mean": np.nanmean(finite, axis=0),
            "std": np.nanstd(finite, axis=0),
            "count": np.asarray([values.shape[0]], dtype=np.int64),
        }
        qs = np.nanquantile(finite, list(QUANTILES.values()), axis=0)
    if values.dtype.kind in "iu":
        out["min"], out["max"] = values.min(axis=0), values.max(axis=0)
    out.update({k: qs[i] for i, k in enumerate(QUANTILES)})
    return out


def _aggregate(parts: Sequence[Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Dataset statistics from episode statistics, as LeRobot aggregates them: exact
    min, max, mean and std; quantiles as the count-weighted mean of the episodes'.
    An episode whose statistic is NaN (no finite value) has no weight in it."""
    counts = np.asarray([float(p["count"][0]) for p in parts])

    def weighted(stack: np.ndarray) -> np.ndarray:
        w = np.where(
            np.isfinite(stack), counts.reshape(-1, *[1] * (stack.ndim - 1)), 0.0
        )
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.nansum(w * np.nan_to_num(stack), axis=0) / w.sum(axis=0)

    means = np.stack([p["mean"] for p in parts])
    mean = weighted(means)
    var = weighted(np.stack([p["std"] ** 2 for p in parts]) + (means - mean) ** 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out = {
            "min": np.nanmin(np.stack([p["min"] for p in parts]), axis=0),
            "max": np.nanmax(np.stack([p["max"] for p in parts]), axis=0),
            "mean": mean,
            "std": np.sqrt(var),
            "count": np.asarray([int(counts.sum())], dtype=np.int64),
        }
    out.update({k: weighted(np.stack([p[k] for p in parts])) for k in QUANTILES})
    return out


def _listed(stats: Mapping[str, np.ndarray]) -> dict[str, list[Any]]:
    return {k: np.atleast_1d(v).tolist() for k, v in stats.items()}


@dataclass
class _Files:
    """The data file being written, rolling to the next at :data:`DATA_FILE_MB`."""

    root: Path
    schema: pa.Schema
    frame_bytes: int
    chunk: int = 0
    file: int = 0
    size: int = 0
    writer: pq.ParquetWriter | None = None
    paths: list[str] = field(default_factory=list)

    def place(self, n_frames: int) -> tuple[int, int]:
        """(chunk, file) the next episode goes to: a new file once this one is full."""
        more = n_frames * self.frame_bytes
        if self.writer is not None and self.size + more > DATA_FILE_MB * 1024**2:
            self.writer.close()
            self.writer, self.size = None, 0
            self.file += 1
            if self.file == CHUNKS_SIZE:
                self.chunk, self.file = self.chunk + 1, 0
        if self.writer is None:
            rel = DATA_PATH.format(chunk_index=self.chunk, file_index=self.file)
            (self.root / rel).parent.mkdir(parents=True, exist_ok=True)
            self.writer = pq.ParquetWriter(
                self.root / rel, self.schema, compression="zstd"
            )
            self.paths.append(rel)
        self.size += more
        return self.chunk, self.file

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None


def _episodes(
    path: Path, stream: str, verify: bool
) -> Iterator[tuple[dict[str, Any], np.ndarray, np.ndarray]]:
    """(trials row, t, values) of every trial with the stream's rows, in order."""
    for chunk in iter_dataset_chunks(path, verify=verify):
        table = chunk.tables[stream]
        rows = table.groupby("trial_id", sort=False).indices
        channels = list(chunk.streams[stream].channels)
        for record in chunk.trials.to_dict("records"):
            row = {str(k): v for k, v in record.items()}
            idx = rows.get(row["trial_id"])
            if idx is None or len(idx) == 0:
                raise SlipkitError(
                    f"{path}: trial {row['trial_id']!r} has no rows in stream "
                    f"{stream!r}; a LeRobot episode needs at least one frame"
                )
            part = table.iloc[idx]
            yield (
                row,
                part["t"].to_numpy(np.float64),
                part[channels].to_numpy(np.float64),
            )


def write_lerobot(
    dataset: Path | str,
    out: Path | str,
    *,
    stream: str | None = None,
    feature: str | None = None,
    task: str | None = None,
    overwrite: bool = False,
    verify: bool = True,
) -> Path:
    """Write the dataset folder ``dataset`` as a LeRobot v3.0 dataset at ``out``.

    Parameters
    ----------
    dataset : path-like
        A slipkit dataset folder (read a chunk of trials at a time).
    out : path-like
        The LeRobot dataset folder to create (atomically; an existing one is replaced
        only with ``overwrite`` and only when slipkit wrote it).
    stream : str, optional
        The sampled stream to write; default: the dataset's only sampled stream.
    feature : str, optional
        The feature's name; default ``observation.<stream>``.
    task : str, optional
        The one task every episode does; default ``"<sensor> recording"``.
    overwrite : bool
        Replace an existing LeRobot dataset that slipkit wrote.
    verify : bool
        Check the dataset's files against their sha256 first.

    Raises
    ------
    SlipkitError
        Naming the option or file at fault: several sampled streams and no
        ``stream``, an event or snapshot stream, a rate below 0.5 Hz, a trial
        without rows in the stream, a feature name LeRobot reserves or with ``/``.
    """
    src = Path(dataset)
    manifest = read_manifest(src)
    target = check_out_path(
        out, inputs={"dataset": src}, kind="lerobot", overwrite=overwrite
    )
    name = _pick_stream(manifest, stream, str(src))
    spec = StreamSpec.from_json(name, manifest["streams"][name])
    assert spec.rate_hz is not None
    fps = round(spec.rate_hz)
    if fps < 1:
        raise SlipkitError(
            f"{src}: stream {name!r} is at {spec.rate_hz:g} Hz; a LeRobot fps is a whole "
            "number >= 1"
        )
    key = feature if feature is not None else f"observation.{name}"
    if not key or "/" in key or key in DEFAULT_FEATURES or key == "task":
        raise SlipkitError(
            f"feature={key}: expected a name without '/' other than "
            f"{', '.join([*DEFAULT_FEATURES, 'task'])}"
        )
    text = task if task is not None else f"{manifest['sensor']} recording"
    n_ch = len(spec.channels)
    schema = pa.schema(
        [
            (key, pa.list_(pa.float64(), n_ch)),
            ("timestamp", pa.float32()),
            *((k, pa.int64()) for k in INDEX_FEATURES),
        ]
    )
    with atomic_dir(target, overwrite=overwrite, kind="lerobot") as tmp:
        files = _Files(tmp, schema, frame_bytes=8 * n_ch + 4 + 8 * len(INDEX_FEATURES))
        episodes: list[dict[str, Any]] = []
        all_stats: list[dict[str, dict[str, np.ndarray]]] = []
        index = 0
        try:
            for k, (row, t, values) in enumerate(_episodes(src, name, verify)):
                n = len(t)
                chunk, file = files.place(n)
                frames: dict[str, np.ndarray] = {
                    "timestamp": t.astype(np.float32),
                    "frame_index": np.arange(n, dtype=np.int64),
                    "episode_index": np.full(n, k, dtype=np.int64),
                    "index": np.arange(index, index + n, dtype=np.int64),
                    "task_index": np.zeros(n, dtype=np.int64),
                }
                column = pa.FixedSizeListArray.from_arrays(
                    pa.array(values.ravel(), pa.float64()), n_ch
                )
                batch = pa.table(
                    [column, *(pa.array(frames[c]) for c in schema.names[1:])],
                    schema=schema,
                )
                assert files.writer is not None
                files.writer.write_table(batch)
                stats = {key: _stats(values)}
                stats.update({c: _stats(v[:, None]) for c, v in frames.items()})
                all_stats.append(stats)
                episodes.append(
                    {
                        "episode_index": k,
                        "tasks": [text],
                        "length": n,
                        "data/chunk_index": chunk,
                        "data/file_index": file,
                        "dataset_from_index": index,
                        "dataset_to_index": index + n,
                        **{
                            f"stats/{f}/{s}": np.atleast_1d(v).tolist()
                            for f, fs in stats.items()
                            for s, v in fs.items()
                        },
                        "meta/episodes/chunk_index": 0,
                        "meta/episodes/file_index": 0,
                        **{f"slipkit/{c}": v for c, v in row.items()},
                    }
                )
                index += n
        finally:
            files.close()
        _write_meta(tmp, episodes, all_stats, text)
        features = {
            key: {"dtype": "float64", "shape": [n_ch], "names": list(spec.channels)},
            **DEFAULT_FEATURES,
        }
        info = {
            "codebase_version": CODEBASE_VERSION,
            "robot_type": None,
            "total_episodes": len(episodes),
            "total_frames": index,
            "total_tasks": 1,
            "chunks_size": CHUNKS_SIZE,
            "data_files_size_in_mb": DATA_FILE_MB,
            "video_files_size_in_mb": VIDEO_FILE_MB,
            "fps": fps,
            "splits": {"train": f"0:{len(episodes)}"},
            "data_path": DATA_PATH,
            "video_path": None,
            "features": features,
        }
        marker = {
            "format": MARKER_FORMAT,
            "written_by": f"slipkit {__version__}",
            "source": {
                "name": manifest.get("name", ""),
                "sensor": manifest["sensor"],
                "files": manifest["files"],
            },
            "stream": name,
            "feature": key,
            "rate_hz": spec.rate_hz,
            "fps": fps,
            "channels": list(spec.channels),
            "units": dict(spec.units),
            "description": spec.description,
            "labels": manifest["labels"],
            "groups": manifest["groups"],
            "task": text,
        }
        _write_json(tmp / "meta" / "info.json", info)
        _write_json(tmp / MARKER, marker)
    return target


def _write_json(path: Path, obj: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=4, allow_nan=False) + "\n", encoding="utf-8")


def _write_meta(
    root: Path,
    episodes: list[dict[str, Any]],
    stats: list[dict[str, dict[str, np.ndarray]]],
    task: str,
) -> None:
    if not episodes:  # pragma: no cover - a dataset has >= 1 trial (its schema says so)
        raise DatasetError(str(root), "no trial to write")
    rel = EPISODES_PATH.format(chunk_index=0, file_index=0)
    (root / rel).parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(episodes).to_parquet(root / rel, index=False, compression="zstd")
    tasks = pd.DataFrame({"task_index": [0]}, index=pd.Index([task]))
    tasks.to_parquet(root / "meta" / "tasks.parquet")
    keys = stats[0].keys()
    total = {k: _listed(_aggregate([s[k] for s in stats])) for k in keys}
    _write_json(root / "meta" / "stats.json", _nan_free(total))


def _nan_free(obj: Any) -> Any:
    """JSON has no NaN: a statistic of a channel without a finite value is null."""
    if isinstance(obj, dict):
        return {k: _nan_free(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_nan_free(v) for v in obj]
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def read_lerobot(path: Path | str) -> Dataset:
    """Read a LeRobot dataset that :func:`write_lerobot` wrote back into a Dataset.

    ``t`` comes back as LeRobot's float32 ``timestamp``; channel values, labels and
    groups as written.

    Raises
    ------
    SlipkitError
        ``path`` holds no ``meta/slipkit.json`` (a LeRobot dataset that slipkit did
        not write: its labels and units are unknown).
    """
    root = Path(path)
    marker_file = root / MARKER
    try:
        marker = json.loads(marker_file.read_text(encoding="utf-8"))
        info = json.loads((root / "meta" / "info.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise SlipkitError(
            f"{root}: not a LeRobot dataset written by slipkit ({exc})"
        ) from exc
    if marker.get("format") != MARKER_FORMAT:
        raise SlipkitError(f"{marker_file}: format is not {MARKER_FORMAT!r}")
    key, name = marker["feature"], marker["stream"]
    episodes = pd.concat(
        [
            pd.read_parquet(p)
            for p in sorted((root / "meta" / "episodes").glob("*/*.parquet"))
        ],
        ignore_index=True,
    ).sort_values("episode_index")
    frames = pa.concat_tables(
        [pq.read_table(p) for p in sorted((root / "data").glob("*/*.parquet"))]
    )
    values = np.asarray(frames[key].combine_chunks().flatten(), dtype=np.float64)
    channels = list(marker["channels"])
    table = pd.DataFrame(values.reshape(-1, len(channels)), columns=channels)
    ids = episodes.set_index("episode_index")["slipkit/trial_id"]
    ep = frames["episode_index"].to_numpy()
    table.insert(0, "t", frames["timestamp"].to_numpy().astype(np.float64))
    table.insert(0, "trial_id", ids.loc[ep].to_numpy())
    order = np.argsort(frames["index"].to_numpy(), kind="stable")
    table = table.iloc[order].reset_index(drop=True)
    cols = [c for c in episodes.columns if c.startswith("slipkit/")]
    trials = episodes[cols].rename(columns=lambda c: c[len("slipkit/") :])
    spec = StreamSpec(
        name,
        tuple(channels),
        marker["units"],
        rate_hz=float(marker["rate_hz"]),
        description=marker.get("description", ""),
    )
    return Dataset(
        sensor=marker["source"]["sensor"],
        streams={name: spec},
        trials=trials.reset_index(drop=True),
        tables={name: table},
        labels={k: LabelSpec.from_json(k, v) for k, v in marker["labels"].items()},
        groups=marker["groups"],
        provenance={"source": str(root), "lerobot": {"fps": info["fps"]}},
        name=marker["source"].get("name", ""),
    )
