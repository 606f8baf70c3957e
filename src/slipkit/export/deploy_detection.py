"""The stream-detection task's deployer: one raw sample per frame, the detector's window
graph, and for a voltage-input FSR detector the ``press_sign`` step (registered with
:mod:`slipkit.export.deploy`)."""

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
    deployed = None
    held = trial_frames(dataset, test_ids, stream, channels)
    from slipkit.baselines.biotac import PressureVibration

    if isinstance(run.model, PressureVibration) and run.model.baseline is None:
        # The batch detector measures its baseline per recording; the graph needs a
        # fixed one: the median over the training recordings (the exporter's helper).
        # The graph then computes the detector with that fixed baseline, so parity
        # checks it against that detector (against the per-recording one the
        # scores differ by the ratio of the baselines, not by rounding), and the note
        # states how often it decides as the trained detector on the held-out trials.
        from slipkit.export.detectors import (
            baseline_agreement,
            pressure_baseline,
            with_fixed_baseline,
        )

        train = [t for t in dataset.trial_ids if str(t) not in set(map(str, test_ids))]
        rec = trial_frames(dataset, train, stream, channels)
        X = np.concatenate([r.frames for r in rec])
        seg = np.concatenate([np.full(len(r.frames), k) for k, r in enumerate(rec)])
        base = pressure_baseline(run.model, X, segments=seg)
        deployed = with_fixed_baseline(run.model, base)
        agree, n = baseline_agreement(
            run.model,
            deployed,
            np.concatenate([r.frames for r in held]),
            segments=np.concatenate(
                [np.full(len(r.frames), k) for k, r in enumerate(held)]
            ),
        )
        notes.append(
            f"fixed pressure baseline {base:.4g} counts RMS (median of the training "
            "recordings; the trained detector measures one per recording): the bundle "
            f"deploys PressureVibration(baseline={base:.4g}), which decides as the "
            f"trained detector on {100 * agree:.2f} % of {n} held-out samples"
        )
    steps: list[dict[str, Any]] = []
    from slipkit.baselines.fsr import FSRTouchSlip

    if isinstance(run.model, FSRTouchSlip) and run.model.input == "voltage":
        # The runtime takes each stream's rest level from its first samples (the
        # press_sign op), as the batch detector does per recording, so a stream of the
        # other wiring is never touched, as in the batch detector; training
        # wirings of both signs: the press direction is latched at its first press
        # too. The graph reads the sign-normalised signal (export_fsr_touch_slip).
        from slipkit.export.detectors import fsr_press_sign_step

        steps = [fsr_press_sign_step(run.model)]
        sign = (
            f"wiring sign (its first block mean further than {steps[0]['delta']:g} V "
            "from rest), as the detector's per-recording polarity"
            if "sign" not in steps[0]
            else f"the fitted polarity's sign ({run.model.polarity_})"
        )
        notes.append(
            "press_sign: the stream's rest level (mean of its first "
            f"{run.model.rest_samples} samples) and {sign}, latched on the gripper "
            "PC; start the loop (or reset it) at rest before each grasp"
        )
    from slipkit.baselines.fsr_onset import FSROnset, slip_sign_step

    if isinstance(run.model, FSROnset):
        # the onset detectors read the same signed signal, per sample (block 1)
        steps = [slip_sign_step(run.model)]
        notes.append(
            "press_sign: the stream's rest level (mean of its first "
            f"{run.model.rest_samples} samples) and its wiring sign, latched on the "
            "gripper PC; start the loop (or reset it) at rest before each grasp"
        )
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


#: A trials column naming the FSR wiring (the fsr_polarity effect); the replay covers each.
WIRING_COLUMN = "fsr_polarity.polarity"


def _detection_classes(
    dataset: Dataset,
    trials: Sequence[HeldOutTrial],
    onset: str | None,
    group_by: str | None,
) -> list[HeldOutTrial]:
    """Held-out recordings with a class (``slip``: a finite ``onset`` label, else
    ``no_slip``; None without the label) and a group (the FSR wiring when the trials
    record it, else ``group_by``), so that the replay samples each."""
    columns = dataset.trials.columns
    group = WIRING_COLUMN if WIRING_COLUMN in columns else group_by
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
