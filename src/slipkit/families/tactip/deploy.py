"""The TacTip frame task's deployer (registered with :mod:`slipkit.export.deploy`).

Frame = the ``pins`` stream (``x0..x{N-1}, y0..y{N-1}``, mm), window 2, hop 1; the
pin-velocity features are inside the graph (``with_features=True``). One
preprocessing step: ``subtract`` a fixed reference frame (the median first frame
of the training trials) in float64 before the float32 cast of the graph input:
absolute positions of ~10 mm in float32 have ~1e-6 mm resolution, resting pins
move ~1e-3 mm per frame, and the offset cancels in the velocity
(``docs/export.md``). Slip class ``slip``; debounce ``task.debounce_k``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.export.deploy import (
    Deployment,
    _frame,
    _rate,
    register_deployer,
    run_metrics,
    trial_frames,
)
from slipkit.train.runs import Run
from slipkit.train.task import Task


def _deploy_tactip(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any]
) -> Deployment:
    from slipkit.data.splits import split_by_trial
    from slipkit.families.tactip.task import TacTipFrames
    from slipkit.features.pins import SLIP

    assert isinstance(task, TacTipFrames)
    from slipkit.models.svm import TacTipSVM

    if not isinstance(run.model, TacTipSVM):
        # the deployed graph computes the pin-velocity features itself (export/pins.py)
        # in front of the SVM's Gemm/Exp graph; other frame classifiers have no such graph
        raise SlipkitError(
            f"run {run.path}: a TacTip frame bundle needs a TacTipSVM (the pin features "
            f"are computed inside its graph); this run's model is "
            f"{type(run.model).__name__}, which slipkit cannot export for TacTip frames "
            "(e.g. configs/model/tactip_nystroem.yaml is for benchmarks/bench_scale.py)"
        )
    stream = task.stream
    rate = _rate(dataset, stream, options)
    channels = list(dataset.streams[stream].channels)
    split = run_metrics(run).get("split", {})
    seed = int(run.config.get("seed", 0))
    if split.get("test"):
        train_ids, test_ids = list(split["train"]), list(split["test"])
    else:  # recompute the task's split (same seed, same call)
        s = split_by_trial(dataset, test_size=task.test_size, val_size=0.0, seed=seed)
        train_ids, test_ids = list(s.train), list(s.test)
    # The fixed reference frame: the median first frame of the training trials (NaN
    # for a pin never seen is 0: it only has to be finite and near the positions).
    firsts = np.stack(
        [tr.frames[0] for tr in trial_frames(dataset, train_ids, stream, channels)]
    )
    with np.errstate(all="ignore"):
        ref = np.nanmedian(np.where(np.isfinite(firsts), firsts, np.nan), axis=0)
    ref = np.where(np.isfinite(ref), ref, 0.0)
    return Deployment(
        frame=_frame([stream], channels, 2, 1, rate),
        preprocessing=[{"op": "subtract", "value": np.round(ref, 6).tolist()}],
        # n_pins: the stream's pin count (a per-pin SVM trained on another refuses it)
        export_options={
            "with_features": True,
            "variant": task.variant,
            "n_pins": len(channels) // 2,
        },
        positive=SLIP,
        debounce_k=int(task.debounce_k),
        trials=trial_frames(dataset, test_ids, stream, channels),
        notes=[
            "raw pin positions in (x block, y block, mm); the graph computes the "
            f"{task.variant} pin-velocity features of the last two frames",
            "preprocessing subtracts a fixed reference frame (median first frame of "
            "the training trials) in float64 before the float32 cast",
        ],
    )


def _register_tactip() -> None:
    from slipkit.families.tactip.task import TacTipFrames

    register_deployer(TacTipFrames, _deploy_tactip)


_register_tactip()
