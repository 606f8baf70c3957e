"""A dataset's summary: what ``slipkit info`` prints."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pandas as pd

from slipkit.data.dataset import Dataset


def summary_dict(dataset: Dataset) -> dict[str, Any]:
    """Trials, streams (rate, channels, rows, duration), labels with class counts, groups."""
    streams: dict[str, Any] = {}
    for name, spec in dataset.streams.items():
        table = dataset.tables[name]
        span = (
            table.groupby("trial_id", sort=False)["t"].agg(
                lambda t: float(t.iloc[-1] - t.iloc[0])
            )
            if len(table)
            else pd.Series(dtype=float)
        )
        streams[name] = {
            "kind": spec.kind,
            "rate_hz": spec.rate_hz,
            "channels": len(spec.channels),
            "channel_names": _abbrev(list(spec.channels)),
            "units": sorted(set(spec.units.values())),
            "rows": len(table),
            "trials_with_stream": int(table["trial_id"].nunique()) if len(table) else 0,
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
        col = dataset.trials[name]
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
    groups = {g: int(dataset.trials[g].nunique()) for g in dataset.groups}
    return {
        "name": dataset.name,
        "sensor": dataset.sensor,
        "trials": len(dataset),
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
    info = summary_dict(dataset)
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
