"""``MODEL_CARD.md``: what a bundle's model is, what it was trained on and how well it did.

:func:`model_card` writes the card ``slipkit export`` puts beside ``manifest.json``
(listed in the manifest's ``files``, so its sha256 is checked like the graph's). It
is written only from what the export already holds: the run folder (``run.json``,
``metrics.json``, ``config.yaml``), the rebuilt dataset (its provenance, trials table
and fingerprint), the manifest (frame, decision, budget, parity) and the session
timing measured at export. A fact none of these holds is written as "not recorded".
"""

from __future__ import annotations

import platform
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from slipkit.data.importers import biotacsp_dos, bts3v2, robotic_finger

NOT_RECORDED = "not recorded"

#: Licence and citation of the public recordings slipkit imports, by importer
#: module: used when a dataset's provenance does not carry them (a dataset folder
#: written before its importer recorded them, or converted by hand).
KNOWN_SOURCES: dict[str, dict[str, str | None]] = {
    "biotacsp_dos": {
        "source": biotacsp_dos.SOURCE,
        "citation": biotacsp_dos.CITATION,
        "license": biotacsp_dos.LICENSE,
    },
    "bts3v2": {
        "source": bts3v2.SOURCE,
        "citation": bts3v2.CITATION,
        "license": bts3v2.LICENSE,
    },
    "robotic_finger": {
        "source": robotic_finger.SOURCE,
        "citation": None,  # the source names no publication
        "license": robotic_finger.LICENSE,
    },
}

#: Trials-table columns the limits section lists the values of, besides the
#: dataset's own group columns.
_SEEN_COLUMNS = ("object", "material", "orientation", "surface", "direction")
_MAX_VALUES = 12
_MAX_METRICS = 30
#: Raw confusion counts: the card gives the rates; metrics.json keeps the counts.
_COUNTS = frozenset({"tp", "fn", "fp", "tn", "n_pos", "n_neg", "n_negative_windows"})


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else :func:`platform.processor`."""
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
    except OSError:
        text = ""
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key.strip() in ("model name", "Model", "Hardware") and value.strip():
            return value.strip()
    return platform.processor() or platform.machine() or NOT_RECORDED


def _fmt(value: Any) -> str:
    if value is None:
        return NOT_RECORDED
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _unit(value: Any, unit: str) -> str:
    """``value unit``, or "not recorded" without the unit."""
    return NOT_RECORDED if value is None else f"{_fmt(value)} {unit}"


def _listing(values: Iterable[Any], limit: int = _MAX_VALUES) -> str:
    items = [str(v) for v in values]
    if not items:
        return "none"
    more = f", ... ({len(items)} in all)" if len(items) > limit else ""
    return ", ".join(items[:limit]) + more


def _short_class(path: str) -> str:
    return path.rsplit(".", 1)[-1] if path else NOT_RECORDED


def _scalars(
    obj: Mapping[str, Any], prefix: str = "", depth: int = 2
) -> list[tuple[str, Any]]:
    """``(dotted key, number)`` of a metrics object, nested dicts to ``depth`` levels."""
    out: list[tuple[str, Any]] = []
    for key, value in obj.items():
        name = f"{prefix}{key}"
        if isinstance(value, bool) or key in _COUNTS:
            continue
        if isinstance(value, int | float):
            out.append((name, value))
        elif isinstance(value, Mapping) and depth > 1:
            out.extend(_scalars(value, name + ".", depth - 1))
    return out


def _table(rows: list[tuple[str, Any]], head: tuple[str, str]) -> list[str]:
    lines = [f"| {head[0]} | {head[1]} |", "|---|---|"]
    lines += [f"| {k} | {_fmt(v)} |" for k, v in rows[:_MAX_METRICS]]
    if len(rows) > _MAX_METRICS:
        lines.append(
            f"| ... | {len(rows) - _MAX_METRICS} more in the run's metrics.json |"
        )
    return lines


def _estimator(model: Any) -> str:
    """The estimator's class, with a pipeline's steps: ``Pipeline(scaler, clf)``."""
    cls = type(model)
    steps = getattr(model, "steps", None)
    inner = (
        "(" + ", ".join(type(step).__name__ for _, step in steps) + ")"
        if isinstance(steps, list)
        else ""
    )
    return f"`{cls.__name__}{inner}` (`{cls.__module__}`)"


def data_source(provenance: Mapping[str, Any]) -> dict[str, Any]:
    """Where the data came from: ``kind`` (simulated / imported / not recorded), name,
    licence and citation, the known-source table filling what the provenance lacks."""
    if provenance.get("scene"):
        return {
            "kind": "simulated",
            "name": str(provenance["scene"]),
            "seed": provenance.get("seed"),
            "effects": list(provenance.get("effects") or []),
            "license": "simulated by slipkit (no external recording)",
            "citation": None,
            "source": None,
        }
    importer = str(provenance.get("importer") or "")
    source = provenance.get("source")
    known: Mapping[str, str | None] = {}
    for key, entry in KNOWN_SOURCES.items():
        if f".importers.{key}." in importer or (source and source == entry["source"]):
            known = entry
            break
    if not provenance:
        kind = NOT_RECORDED
    else:
        kind = "recorded" if source or importer else NOT_RECORDED
    return {
        "kind": kind,
        "name": _short_class(importer.rsplit(".", 1)[0]) if importer else None,
        "source": source or known.get("source"),
        "license": provenance.get("license") or known.get("license"),
        "citation": provenance.get("citation") or known.get("citation"),
        "importer": importer or None,
        "assumptions": list(provenance.get("assumptions") or []),
    }


def _ids(value: Any) -> list[str] | None:
    """Trial ids of a split side: a list of ids, or of folds' lists (flattened)."""
    if not isinstance(value, list):
        return None
    out: list[str] = []
    for v in value:
        if isinstance(v, list):
            out.extend(str(x) for x in v)
        else:
            out.append(str(v))
    return out


def _split(metrics: Mapping[str, Any], task_cfg: Mapping[str, Any]) -> dict[str, Any]:
    sp = metrics.get("split") if isinstance(metrics.get("split"), Mapping) else {}
    assert isinstance(sp, Mapping)
    by = sp.get("by") or metrics.get("split_by") or task_cfg.get("split")
    if by is None and isinstance(sp.get("block_s"), int | float):
        by = f"time blocks of {sp['block_s']:g} s"
    group = task_cfg.get("group") or (
        sp.get("by") if sp.get("by") not in (None, "trial") else None
    )
    train, test = _ids(sp.get("train")), _ids(sp.get("test"))
    return {
        "by": by,
        "group": group,
        "train": train,
        "test": test,
        "n_train": len(train) if train is not None else sp.get("n_train"),
        "n_test": len(test) if test is not None else sp.get("n_test"),
        "folds": sp.get("folds"),
        "test_size": task_cfg.get("test_size"),
        "train_groups": sp.get("train_objects"),
        "test_groups": sp.get("test_objects"),
        "fold_groups": sp.get("test_groups"),
        # counts per side in other units (time blocks, frames)
        "counts": {
            unit: counts
            for unit in ("blocks", "frames")
            if isinstance(counts := sp.get(unit), Mapping)
        },
    }


def _controls(metrics: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """The run's controls (first frame, dynamics only, majority class, ...) as rows."""
    rows: list[tuple[str, Any]] = []
    in_blocks = {
        f"{name}_accuracy"
        for key in ("controls", "controls_test")
        if isinstance(metrics.get(key), Mapping)
        for name in metrics[key]
    }
    for key, value in metrics.items():
        if key in in_blocks:
            continue  # the same figure as its block's entry below
        if key.startswith(("first_frame", "dynamics", "majority")):
            if isinstance(value, int | float) and not isinstance(value, bool):
                rows.append((key, value))
            elif isinstance(value, Mapping):
                rows += [(f"{key}.{k}", v) for k, v in _scalars(value, depth=1)]
    for key in ("controls", "controls_test"):
        block = metrics.get(key)
        if not isinstance(block, Mapping):
            continue
        for name, entry in block.items():
            if not isinstance(entry, Mapping):
                continue
            for where in (entry, entry.get("window"), entry.get("test")):
                if isinstance(where, Mapping):
                    picked = [
                        (f"{key}.{name}.{m}", where[m])
                        for m in ("accuracy", "balanced_accuracy")
                        if isinstance(where.get(m), int | float)
                    ]
                    if picked:
                        rows += picked
                        break
    return rows


def _range(values: Any) -> str:
    """``a to b`` of a numeric column's finite values."""
    v = pd.to_numeric(values, errors="coerce").dropna()
    return f"{_fmt(float(v.min()))} to {_fmt(float(v.max()))}" if len(v) else "none"


def _seen(dataset: Any, split: Mapping[str, Any]) -> list[str]:
    """Values of the group / object-like columns on each side of the split."""
    trials = dataset.trials
    cols = [c for c in dict.fromkeys([*dataset.groups, *_SEEN_COLUMNS]) if c in trials]
    labels = set(getattr(dataset, "labels", {}) or {})
    lines = []
    if split["train"] is None and split["train_groups"] is not None:
        lines.append(
            f"`{split['group'] or 'group'}` seen in training: "
            f"{_listing(split['train_groups'])}; held out: {_listing(split['test_groups'] or [])}"
        )
        cols = [c for c in cols if c != split["group"]]
    for col in cols:
        if col in labels:
            continue
        ids = trials["trial_id"].astype(str)
        numeric = pd.api.types.is_numeric_dtype(trials[col])
        if split["train"] is not None and split["test"] is not None:
            tr = trials.loc[ids.isin(split["train"]), col]
            te = trials.loc[ids.isin(split["test"]), col]
            if numeric:
                lines.append(f"`{col}` in training {_range(tr)}; held out {_range(te)}")
                continue
            seen, held = sorted(set(tr.astype(str))), sorted(set(te.astype(str)))
            unseen = sorted(set(held) - set(seen))
            lines.append(
                f"`{col}` seen in training: {_listing(seen)}; held out: {_listing(held)}"
                + (f" ({len(unseen)} never seen in training)" if unseen else "")
            )
        elif numeric:
            lines.append(f"`{col}` in the dataset {_range(trials[col])}")
        else:
            folds = split["fold_groups"] if col == split["group"] else None
            lines.append(
                f"`{col}` in the dataset: {_listing(sorted(set(trials[col].astype(str))))}"
                + (
                    f"; the {len(folds)} outer folds hold out "
                    + " | ".join(_listing(f, 6) for f in folds)
                    if isinstance(folds, list) and folds
                    else ""
                )
            )
    return lines


def model_card(
    manifest: Mapping[str, Any],
    run: Any,
    dataset: Any,
    *,
    kind: str,
    latency: Mapping[str, Any] | None,
    latency_note: str,
    debounce_from: str,
    model_sha256: str,
    threshold_from: str | None = None,
) -> str:
    """The Markdown text of ``MODEL_CARD.md`` for a bundle being exported.

    Parameters
    ----------
    manifest : mapping
        The bundle's manifest as exported (``frame``, ``decision``, ``budget_ms``,
        ``training`` with its parity record, ``producer``).
    run : slipkit.train.runs.Run
        The run folder read back (``info`` = run.json, ``metrics``, ``config``).
    dataset : slipkit.data.Dataset
        The training data the export rebuilt (its fingerprint matched the run's).
    kind : {"learned", "analytic"}
        Whether the estimator learns a model or calibrates a fixed rule.
    latency : mapping, optional
        ``{"p50_ms", "p99_ms", "session", "frames", "rounds"}`` measured at export;
        None when the export measured none (``latency_note`` says why).
    latency_note : str
        How the latency was measured, or why it was not.
    debounce_from : str
        Where the deployed debounce comes from.
    model_sha256 : str
        sha256 of ``model.onnx``.
    threshold_from : str, optional
        Where the threshold comes from when the export set it (a regressor's
        ``regression.threshold``); else the run's record is read.
    """
    info, metrics = run.info, run.metrics
    task_cfg = dict(run.config.get("task") or {})
    training = manifest.get("training") or {}
    decision = manifest.get("decision") or {}
    frame = manifest.get("frame") or {}
    budget = manifest.get("budget_ms") or {}
    src = data_source(dataset.provenance)
    split = _split(metrics, task_cfg)
    ds_info = info.get("dataset") or {}
    lines = [f"# Model card: {manifest.get('name', NOT_RECORDED)}", ""]

    # -- what the model is
    classes = decision.get("classes") or []
    predicts = (
        f"classes {_listing(classes)}; slip when "
        + (
            f"the largest score is one of {_listing(decision.get('slip_classes') or [])}"
            if decision.get("rule") == "argmax"
            else f"score column {decision.get('column', 0)} crosses the threshold "
            f"(slip class `{decision.get('positive', NOT_RECORDED)}`)"
        )
        if classes
        else f"a regression score, slip above the threshold (column {decision.get('column', 0)})"
    )
    lines += [
        "## Model",
        "",
        f"- Estimator: {_estimator(run.model)} (config `{info.get('model', NOT_RECORDED)}`), "
        f"{kind}",
        f"- Task: `{_short_class(str(info.get('task', '')))}`; experiment "
        f"`{info.get('name') or NOT_RECORDED}`; sensor family `{dataset.sensor}`",
        f"- Predicts: {predicts}",
        f"- Score: {training.get('score') or NOT_RECORDED}",
        f"- Run: `{run.path.name}`, created {info.get('created_utc') or NOT_RECORDED} "
        f"by {info.get('written_by') or NOT_RECORDED}, seed {_fmt(info.get('seed'))}",
        f"- Graph: `model.onnx` opset {_fmt(manifest.get('opset'))}, sha256 "
        f"`{model_sha256}`",
        "",
    ]

    # -- sensor and frame
    streams = frame.get("streams") or []
    rates = [
        f"{s} {_fmt(dataset.streams[s].rate_hz)} Hz"
        for s in streams
        if s in dataset.streams
    ]
    ops = [str(step.get("op")) for step in manifest.get("preprocessing") or []]
    lines += [
        "## Sensor and frame",
        "",
        f"- Streams: {_listing(streams)} ({_listing(rates) if rates else 'rate ' + NOT_RECORDED})",
        f"- Channels ({len(frame.get('channels') or [])}): {_listing(frame.get('channels') or [], 8)}",
        f"- Frame shape {frame.get('shape') or NOT_RECORDED}, {_unit(frame.get('rate_hz'), 'Hz')}; window "
        f"{_fmt(frame.get('window'))} frames, decision every {_fmt(frame.get('hop'))}",
        f"- Preprocessing: {_listing(ops) if ops else 'none (the graph takes the window)'}",
        f"- Budget: frame period {_unit(budget.get('frame_period'), 'ms')}, p99 <= "
        f"{_unit(budget.get('p99'), 'ms')} (from {budget.get('source') or NOT_RECORDED})",
        "",
    ]

    # -- training data
    lines += ["## Training data", ""]
    lines.append(
        f"- Dataset `{dataset.name or ds_info.get('name') or NOT_RECORDED}`: "
        f"{len(dataset)} trials, fingerprint `{ds_info.get('fingerprint') or dataset.fingerprint()}`"
    )
    if src["kind"] == "simulated":
        lines.append(
            f"- Source: simulated scene `{src['name']}`, seed {_fmt(src['seed'])}"
            + (f", effects {_listing(src['effects'])}" if src["effects"] else "")
        )
    else:
        where = ds_info.get("path") or ds_info.get("raw")
        lines.append(
            f"- Source: {src['kind']} data"
            + (f" from {src['source']}" if src["source"] else "")
            + (f" (importer `{src['importer']}`)" if src.get("importer") else "")
            + (f"; dataset folder `{where}`" if where else "")
        )
    lines.append(f"- Licence: {src['license'] or NOT_RECORDED}")
    lines.append(f"- Citation: {src['citation'] or NOT_RECORDED}")
    for note in src.get("assumptions") or []:
        lines.append(f"- Import assumption: {note}")
    sizes = (
        f"{_fmt(split['n_train'])} training / {_fmt(split['n_test'])} test trials"
        if split["n_train"] is not None
        else "; ".join(
            f"{unit}: " + ", ".join(f"{side} {n}" for side, n in counts.items())
            for unit, counts in split["counts"].items()
        )
        if split["counts"] and split["n_test"] is None
        else f"{_fmt(split['n_test'])} test trials"
        + (f" over {split['folds']} outer folds" if split["folds"] else "")
    )
    validation = (
        metrics.get("validation")
        if isinstance(metrics.get("validation"), Mapping)
        else {}
    )
    assert isinstance(validation, Mapping)
    cv = validation.get("cv")
    by = (
        split["by"]
        if split["by"] is not None
        else "whole trials (each side's trial ids recorded; split kind not recorded)"
        if split["train"] is not None
        else None
    )
    lines.append(
        f"- Split: by {_fmt(by)}"
        + (f" (group column `{split['group']}`)" if split["group"] else "")
        + f"; {sizes}"
        + (
            f"; test_size {_fmt(split['test_size'])}"
            if split["test_size"] is not None and not split["folds"]
            else ""
        )
        + f"; run seed {_fmt(info.get('seed'))}"
        + (
            f", simulation seed {_fmt(src['seed'])}"
            if src["kind"] == "simulated"
            else ""
        )
    )
    lines.append(
        f"- Model choice: {cv + (', k=' + str(validation['k']) if validation.get('k') else '') if cv else NOT_RECORDED}"
        f" on the training side; objective {_fmt((info.get('objective') or {}).get('name'))}"
        f" = {_fmt((info.get('objective') or {}).get('value'))}"
    )
    lines.append("")

    # -- held-out metrics
    test = metrics.get("test") if isinstance(metrics.get("test"), Mapping) else None
    held = training.get("held_out")
    lines += [
        "## Held-out metrics",
        "",
        f"Scored on: {training.get('scored_on') or NOT_RECORDED}"
        + ("" if held is not False else "; the saved model was then refit on all data")
        + (f"; test trials {_listing(split['test'], 6)}" if split["test"] else "")
        + ".",
        "",
    ]
    lines += (
        _table(_scalars(test), ("metric", "value"))
        if test
        else [f"Test metrics: {NOT_RECORDED}."]
    )
    controls = _controls(metrics)
    lines += ["", "Controls on the same test split:", ""]
    lines += (
        _table(controls, ("control", "value"))
        if controls
        else [f"{NOT_RECORDED} for this run."]
    )
    parity = training.get("parity") or {}
    lines += [
        "",
        f"Parity of the ONNX graph with the estimator: decisions agree on "
        f"{_fmt(100 * parity['agreement']) if isinstance(parity.get('agreement'), int | float) else NOT_RECORDED} % "
        f"of {_fmt(parity.get('n_frames'))} held-out calls, max |score difference| "
        f"{_fmt(parity.get('max_abs_diff'))}.",
        "",
    ]

    # -- operating point
    op = (
        metrics.get("operating_point")
        if isinstance(metrics.get("operating_point"), Mapping)
        else {}
    )
    assert isinstance(op, Mapping)
    threshold = manifest.get("threshold", decision.get("threshold"))
    chosen_on = op.get("chosen_on")
    op_val = op.get("validation") if isinstance(op.get("validation"), Mapping) else {}
    assert isinstance(op_val, Mapping)
    lines += [
        "## Operating point",
        "",
        "- Threshold: "
        + (
            "none (argmax rule)"
            if threshold is None
            else f"{_fmt(threshold)}, {threshold_from}"
            if threshold_from
            else f"{_fmt(threshold)}, chosen by {metrics['threshold_from']}"
            if metrics.get("threshold_from")
            else f"{_fmt(threshold)}, the model's own decision boundary"
            if op and op.get("threshold") is None
            else f"{_fmt(threshold)} (how it was chosen: {NOT_RECORDED})"
        ),
        f"- Operating point chosen by: {op.get('from') or NOT_RECORDED}",
        f"- Debounce: {_fmt((manifest.get('debounce') or {}).get('k'))} consecutive slip "
        f"decisions; {debounce_from}",
    ]
    if chosen_on:
        lines.append(f"- Chosen on trials: {_listing(chosen_on, 6)}")
    if op_val:
        keep = ("detected_rate", "early_alarm_rate", "false_alarms_per_min", "delay_ms")
        lines.append(
            "- At this point on validation: "
            + ", ".join(f"{k} {_fmt(op_val.get(k))}" for k in keep)
        )
    if op.get("note"):
        lines.append(f"- Note: {op['note']}")
    lines.append("")

    # -- latency
    lines += ["## Latency", ""]
    if latency:
        lines.append(
            f"- Loop p50 {_fmt(1e3 * float(latency['p50_ms']))} us, p99 "
            f"{_fmt(1e3 * float(latency['p99_ms']))} us per decision against the budget p99 "
            f"{_unit(budget.get('p99'), 'ms')}"
        )
    else:
        lines.append(f"- Loop p50 / p99: {NOT_RECORDED}")
    lines += [
        f"- Measured: {latency_note}",
        f"- CPU: {cpu_model()}; onnxruntime "
        f"{(manifest.get('producer') or {}).get('onnxruntime') or NOT_RECORDED}",
        "- On the gripper PC: `slipkit-run BUNDLE --check` measures it there.",
        "",
    ]

    # -- intended use and limits
    lines += ["## Intended use and limits", ""]
    lines.append(
        f"- Intended use: {'slip decisions' if classes else 'a thresholded estimate'} from a "
        f"`{dataset.sensor}` sensor streaming {_listing(streams) if streams else NOT_RECORDED} "
        f"at {_unit(frame.get('rate_hz'), 'Hz')}, the channel layout above"
    )
    if src["kind"] == "simulated":
        lines.append(
            "- Trained and scored on simulated scenes only; not checked on real recordings"
        )
    elif src["kind"] == "recorded":
        lines.append(
            f"- Trained and scored on recordings of one source ({src['source'] or NOT_RECORDED}); "
            "other sensors, mountings and objects not checked"
        )
    else:
        lines.append(
            f"- Data source: {NOT_RECORDED}; check it before relying on the scores"
        )
    lines += [f"- {line}" for line in _seen(dataset, split)]
    if held is False:
        lines.append(
            "- The saved model was refit on all data after it was scored: the metrics "
            "above are those of the models scored on held-out data before the refit, "
            "not of this model on unseen data"
        )
    lines.append(
        f"- Replay in the bundle: {training.get('replay', {}).get('note') or NOT_RECORDED}"
    )
    lines.append("")
    return "\n".join(lines)


__all__ = ["KNOWN_SOURCES", "NOT_RECORDED", "cpu_model", "data_source", "model_card"]
