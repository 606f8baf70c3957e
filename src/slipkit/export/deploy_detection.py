"""The stream-detection task's deployer: one raw sample per frame, the detector's window
graph, and the runtime steps its exporter registers (:func:`slipkit.export.registry.runtime_steps`,
e.g. a voltage-input detector's ``press_sign``); registered with :mod:`slipkit.export.deploy`.
It names no sensor family: the replay's groups come from the effects that declare them
(``replay_groups`` of :func:`slipkit.sim.core.register_effect`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from slipkit.data.dataset import Dataset
from slipkit.export.deploy import (
    Deployment,
    HeldOutTrial,
    _frame,
    _rate,
    run_metrics,
    trial_classes,
    trial_frames,
)
from slipkit.export.registry import StreamContext, runtime_steps
from slipkit.train.runs import Run
from slipkit.train.task import Task


def _deploy_detection(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any]
) -> Deployment:
    from slipkit.data.splits import split_by_trial
    from slipkit.train.tasks.detection import StreamDetection

    assert isinstance(task, StreamDetection)
    stream = task.stream
    rate = _rate(dataset, stream, options)
    channels = (
        list(dataset.streams[stream].channels)
        if task.channels is None
        else list(task.channels)
    )
    split = run_metrics(run).get("split", {})
    if split.get("test"):
        test_ids = list(split["test"])
    else:  # the task's own split: by trial, its test_size, the run's seed
        seed = int(run.config.get("seed", 0))
        test_ids = list(
            split_by_trial(dataset, test_size=task.test_size, seed=seed).test
        )
    classes = [str(c) for c in getattr(run.model, "classes_", ["0", "1"])]
    positive = str(options.get("positive") or classes[-1])
    export_options: dict[str, Any] = {}
    notes = []
    held = trial_frames(dataset, test_ids, stream, channels)
    held_ids = set(map(str, test_ids))
    extra = runtime_steps(
        run.model,
        StreamContext(
            stream=stream,
            channels=channels,
            train_ids=[t for t in dataset.trial_ids if str(t) not in held_ids],
            held=held,
            frames=lambda ids: trial_frames(dataset, ids, stream, channels),
        ),
    )
    steps = extra.steps
    notes.extend(extra.notes)
    deployed = extra.model
    return Deployment(
        # window and hop come from the graph (DetectorGraph.window / .hop)
        frame=_frame([stream], channels, 1, 1, rate),
        preprocessing=steps,
        export_options=export_options,
        positive=positive,
        debounce_k=int(options.get("debounce_k") or 1),
        trials=_detection_classes(dataset, held, task.label, task.group_by),
        model=deployed,
        notes=[
            f"raw samples of {stream!r} ({', '.join(channels)}) at {rate:g} Hz; the graph "
            f"holds {type(run.model).__name__}'s math on a window of the last samples",
            *notes,
        ],
        detector=True,
    )


def _detection_classes(
    dataset: Dataset,
    trials: Sequence[HeldOutTrial],
    onset: str | None,
    group_by: str | None,
) -> list[HeldOutTrial]:
    """Held-out recordings with a class (``slip``: a finite ``onset`` label, else
    ``no_slip``; None without the label) and a group (the first column the trials
    record of an effect's ``replay_groups``, such as a sensor's wiring, else
    ``group_by``), so that the replay samples each."""
    # importing slipkit.sim registers every effect, family folders' included
    from slipkit.sim.core import replay_groups

    columns = dataset.trials.columns
    group = next((c for c in replay_groups() if c in columns), group_by)
    out = trial_classes(dataset, trials, None, group)
    if onset is None or onset not in columns:
        return out
    table = dataset.trials.set_index(dataset.trials["trial_id"].astype(str))
    labelled = []
    for t in out:
        value = _as_float(table.at[t.trial_id, onset])
        label = "slip" if np.isfinite(value) else "no_slip"
        labelled.append(
            HeldOutTrial(t.trial_id, t.frames, t.timestamps, t.keep, label, t.group)
        )
    return labelled


def _as_float(value: Any) -> float:
    """A table cell as a float (NaN when it is missing or not a number)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan
