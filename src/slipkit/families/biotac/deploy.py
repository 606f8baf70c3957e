"""The BioTac force regression's deployer (registered with :mod:`slipkit.export.deploy`).

Frame = one electrode frame (window 1, hop 1). With ``baseline: first`` one
step, ``baseline_first`` (``frames = task.baseline_frames``): the runtime takes
the baseline from the first ``baseline_frames`` frames of the stream (start the
loop before contact, as each simulated trial starts at rest; until they have
arrived, the median of those that have). A regressor has no classes: the
decision is ``score[axis] > threshold`` (N) on the axis and threshold the export
config gives (``regression``), recorded without ``classes``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.export.deploy import (
    Deployment,
    HeldOutTrial,
    _frame,
    _rate,
    register_deployer,
    trial_frames,
)
from slipkit.families.biotac.force_task import ForceRegression
from slipkit.train.runs import Run
from slipkit.train.task import Task


def _deploy_force(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any]
) -> Deployment:
    assert isinstance(task, ForceRegression)
    if task.pdc_stream is not None:
        raise SlipkitError(
            "slipkit export: ForceRegression with task.pdc_stream (two input streams "
            "in one frame) is not deployable yet; train with pdc_stream=null"
        )
    stream = task.stream
    rate = _rate(dataset, stream, options)
    channels = list(dataset.streams[stream].channels)
    seed = int(run.config.get("seed", 0))
    frames = task.frames(dataset)
    sides, _ = task.sides(dataset, frames, seed=seed)
    test_rows = set(frames.row[sides.test].tolist())
    test_trials = list(dict.fromkeys(frames.trial[sides.test].tolist()))
    trials = trial_frames(dataset, test_trials, stream, channels)
    # Mark the test-block frames of each trial (rows of the long stream table).
    table = dataset.stream(stream).reset_index(drop=True)
    rows_of = table.groupby(table["trial_id"].astype(str), sort=False).indices
    kept = []
    for tr in trials:
        idx = rows_of[tr.trial_id]
        order = np.argsort(table["t"].to_numpy()[idx], kind="stable")
        keep = np.isin(idx[order], list(test_rows))
        kept.append(HeldOutTrial(tr.trial_id, tr.frames, tr.timestamps, keep))
    axes = list(task.axes)
    reg = dict(options.get("regression") or {})
    axis = str(reg.get("axis") or axes[-1])
    if axis not in axes:
        raise SlipkitError(
            f"regression.axis {axis!r} is not one of the task's axes {axes}"
        )
    raw_thr = reg.get("threshold")
    threshold = 0.0 if raw_thr is None else float(raw_thr)
    steps: list[dict[str, Any]] = []
    notes = [f"electrode frames of stream {stream!r} (counts), one per model call"]
    if task.baseline == "first":
        steps.append(
            {"op": "baseline_first", "frames": int(task.baseline_frames), "hop": 1}
        )
        notes.append(
            f"baseline: median of the first {int(task.baseline_frames)} frames of the "
            "stream, subtracted from every frame (start the loop before contact)"
        )
    notes.append(
        f"decision: {axis} > {threshold:g} N (a force estimate has no slip class)"
    )
    return Deployment(
        frame=_frame([stream], channels, 1, 1, rate),
        preprocessing=steps,
        export_options={},
        positive=None,
        debounce_k=int(options.get("debounce_k") or 1),
        trials=kept,
        notes=notes,
        regression={
            "axis": axis,
            "column": axes.index(axis),
            "threshold": threshold,
        },
    )


register_deployer(ForceRegression, _deploy_force)
