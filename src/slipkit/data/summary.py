"""A dataset's summary: what ``slipkit info`` prints.

:func:`summary_dict` summarises a dataset in memory; :func:`summary_of_folder` gives the
same summary of a dataset folder while holding only a few trials at a time
(:func:`slipkit.data.io.iter_dataset_chunks`), so the memory ``slipkit info`` needs
does not grow with the recording's length.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import Dataset
from slipkit.data.io import CHUNK_VALUES, iter_dataset_chunks


def _spans(table: pd.DataFrame) -> pd.Series:
    """Per trial of a long table, last minus first time stamp (s), in table order."""
    if not len(table):
        return pd.Series(dtype=float)
    return table.groupby("trial_id", sort=False)["t"].agg(
        lambda t: float(t.iloc[-1] - t.iloc[0])
    )


def summary_dict(dataset: Dataset) -> dict[str, Any]:
    """Trials, streams (rate, channels, rows, duration), labels with class counts, groups."""
    stats = {
        name: (len(table), _spans(table)) for name, table in dataset.tables.items()
    }
    return _summary(dataset, dataset.trials, stats)


def summary_of_folder(
    path: Path | str, *, verify: bool = True, max_values: int = CHUNK_VALUES
) -> dict[str, Any]:
    """:func:`summary_dict` of the dataset folder ``path``, read a chunk of trials at a time.

    Every check of :func:`slipkit.data.io.load_dataset` runs; the peak memory is that of
    one chunk (about ``max_values`` stream values) plus one number per trial.
    """
    trials: list[pd.DataFrame] = []
    rows: dict[str, int] = {}
    spans: dict[str, list[pd.Series]] = {}
    last: Dataset | None = None
    for part in iter_dataset_chunks(path, verify=verify, max_values=max_values):
        trials.append(part.trials)
        for name, table in part.tables.items():
            rows[name] = rows.get(name, 0) + len(table)
            spans.setdefault(name, []).append(_spans(table))
        last = part
    assert last is not None  # iter_dataset_chunks refuses a dataset without trials
    stats = {
        name: (
            rows[name],
            pd.concat([s for s in spans[name] if len(s)])
            if any(len(s) for s in spans[name])
            else pd.Series(dtype=float),
        )
        for name in last.streams
    }
    return _summary(last, pd.concat(trials, ignore_index=True), stats)


def _summary(
    dataset: Dataset,
    trials: pd.DataFrame,
    stats: dict[str, tuple[int, pd.Series]],
) -> dict[str, Any]:
    """The summary from ``dataset``'s specs, the whole trials table and, per stream,
    its row count and per-trial spans (s)."""
    streams: dict[str, Any] = {}
    for name, spec in dataset.streams.items():
        n_rows, span = stats[name]
        streams[name] = {
            "kind": spec.kind,
            "rate_hz": spec.rate_hz,
            "channels": len(spec.channels),
            "channel_names": _abbrev(list(spec.channels)),
            "units": sorted(set(spec.units.values())),
            "rows": n_rows,
            "trials_with_stream": len(span),
            "duration_s": None
            if spec.kind == "snapshot" or span.empty
            else {
                "min": round(float(span.min()), 4),
                "mean": round(float(span.mean()), 4),
                "max": round(float(span.max()), 4),
                "total": round(float(span.sum()), 3),
            },
        }
    labels: dict[str, Any] = {}
    for name, lab in dataset.labels.items():
        col = trials[name]
        if lab.classes is not None:
            counts = col.astype(str).value_counts()
            labels[name] = {c: int(counts.get(c, 0)) for c in lab.classes}
        else:
            values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=float)
            finite = values[np.isfinite(values)]
            labels[name] = {
                "unit": lab.unit,
                "known": int(finite.size),
                "missing": int(values.size - finite.size),
                **(
                    {"min": float(finite.min()), "max": float(finite.max())}
                    if finite.size
                    else {}
                ),
            }
    groups = {g: int(trials[g].nunique()) for g in dataset.groups}
    return {
        "name": dataset.name,
        "sensor": dataset.sensor,
        "trials": len(trials),
        "streams": streams,
        "labels": labels,
        "groups": groups,
        "provenance": dataset.provenance,
    }


def _abbrev(names: list[str], keep: int = 3) -> str:
    if len(names) <= 2 * keep:
        return ", ".join(names)
    return ", ".join(names[:keep]) + ", ..., " + ", ".join(names[-keep:])


def summarize(dataset: Dataset) -> str:
    """Human-readable summary of a dataset (the text ``slipkit info`` prints)."""
    return format_summary(summary_dict(dataset))


def format_summary(info: dict[str, Any]) -> str:
    """The text of a summary made by :func:`summary_dict` or :func:`summary_of_folder`."""
    lines = [
        f"dataset   {info['name']}",
        f"sensor    {info['sensor']}",
        f"trials    {info['trials']}",
        "streams",
    ]
    for name, s in info["streams"].items():
        rate = f"{s['rate_hz']:g} Hz" if s["rate_hz"] else s["kind"]
        dur = s["duration_s"]
        dur_txt = (
            ""
            if dur is None
            else f", {dur['min']:g}-{dur['max']:g} s per trial ({dur['total']:g} s in all)"
        )
        lines.append(
            f"  {name:<14} {rate:>10}  {s['channels']:>3} ch [{s['channel_names']}] "
            f"in {'/'.join(s['units'])}, {s['rows']} rows{dur_txt}"
        )
    if info["labels"]:
        lines.append("labels")
        for name, lab in info["labels"].items():
            if "known" in lab:
                rng = f", {lab['min']:g}..{lab['max']:g}" if "min" in lab else ""
                lines.append(
                    f"  {name:<18} {lab['known']} known, {lab['missing']} missing ({lab['unit']}){rng}"
                )
            else:
                lines.append(
                    f"  {name:<18} " + ", ".join(f"{c}: {n}" for c, n in lab.items())
                )
    if info["groups"]:
        lines.append(
            "groups    "
            + ", ".join(f"{g} ({n} values)" for g, n in info["groups"].items())
        )
    if info["provenance"]:
        lines.append(
            "provenance "
            + json.dumps(info["provenance"], sort_keys=True, default=str)[:400]
        )
    return "\n".join(lines)
