"""The DAVIS release task's deployers (registered with :mod:`slipkit.export.deploy`).

``DavisRelease``
    Frame = one 10 ms event frame ``[2, H, W]`` (positive and negative counts per
    pixel), window 1, hop 1. One preprocessing step, ``davis_areas`` (the detector's
    opening, closing and connected-component area filter in numpy: ONNX has no op
    for connected components), then a two-row graph for the polarity rule
    (:mod:`.export.polarity`); parity: the op's areas equal the detector's on every
    held-out frame. The onset rule: one ``frame_s`` event frame, no preprocessing, the
    whole rule in the graph (:mod:`.export.onset`). The learned
    ``EventFrameClassifier``: one ``frame_s`` (20 ms) event frame, no preprocessing, the
    counts, areas, scaler and logistic regression in the graph
    (:mod:`.export.classifier`); parity: the frames' features equal the classifier's on
    every held-out frame, then the graph's logit the classifier's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.export.deploy import (
    Deployment,
    HeldOutTrial,
    register_deployer,
    run_metrics,
)
from slipkit.runtime.preprocessing import Pipeline
from slipkit.train.runs import Run
from slipkit.train.task import Task

#: replay bytes a DAVIS bundle may hold (float64 event frames of 2 x H x W values)
DAVIS_REPLAY_BYTES = 128 << 20


def davis_event_frames(
    events: NDArray[np.float64], *, frame_s: float, height_px: int, width_px: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One recording's events ``(t, x, y, polarity)`` as the runtime's event frames.

    Frame ``k`` holds the events with ``k frame_s <= t < (k + 1) frame_s`` (the
    detector's grid, frames 0 to the last event's), as counts per pixel: channel 0
    positive, channel 1 negative. Its timestamp is the window's end (s), when the
    frame is complete.

    Returns
    -------
    frames : ndarray of shape (n_frames, 2, height_px, width_px)
    timestamps : ndarray of shape (n_frames,)
    """
    ev = np.asarray(events, dtype=np.float64).reshape(-1, 4)
    n = int(np.floor(ev[-1, 0] / frame_s)) + 1 if len(ev) else 0
    frames: NDArray[np.float64] = np.zeros((n, 2, int(height_px), int(width_px)))
    if len(ev):
        k = np.floor(ev[:, 0] / frame_s).astype(np.intp)
        ch = (ev[:, 3] < 0).astype(np.intp)
        np.add.at(
            frames, (k, ch, ev[:, 2].astype(np.intp), ev[:, 1].astype(np.intp)), 1
        )
    times = (np.arange(n, dtype=np.float64) + 1.0) * frame_s
    return frames, times


def davis_debounce(run: Run, options: Mapping[str, Any]) -> int:
    """The debounce a DAVIS bundle deploys: the export's ``debounce_k``, else the run's
    operating point (chosen on its training trials by ``DavisRelease``), else 1."""
    k = options.get("debounce_k")
    if k is None:
        k = (run_metrics(run).get("operating_point") or {}).get("debounce_k")
    if k is None:
        k = getattr(run.model, "debounce_k_", None)
    return int(k) if k is not None else 1


def _davis_held_out(
    task: Any,
    run: Run,
    dataset: Dataset,
    frame_s: float,
    h: int,
    w: int,
    check: Callable[[Any, NDArray[np.float64], NDArray[Any]], None],
) -> list[HeldOutTrial]:
    """The run's held-out DAVIS trials as runtime event frames, each checked by ``check``.

    ``check(trial, events, frames)`` raises when the runtime's view of a trial's frames
    differs from the training side's (the deployer's parity before anything is written).
    """
    split = run_metrics(run).get("split", {})
    if split.get("test"):
        test_ids = {str(t) for t in split["test"]}
    else:  # the task's own split, the run's seed
        from slipkit.data.splits import split_by_trial

        seed = int(run.config.get("seed", 0))
        test_ids = {
            str(t)
            for t in split_by_trial(dataset, test_size=task.test_size, seed=seed).test
        }
    trials = []
    for trial in dataset.subset([t for t in dataset.trial_ids if str(t) in test_ids]):
        table = trial.streams[task.stream].sort_values("t", kind="stable")
        ev = table[["t", "x", "y", "polarity"]].to_numpy(np.float64)
        frames, times = davis_event_frames(ev, frame_s=frame_s, height_px=h, width_px=w)
        if not len(frames):
            continue
        check(trial, ev, frames)
        label = str(int(np.isfinite(float(trial.labels.get(task.label, np.inf)))))
        group = trial.meta.get(task.group)
        trials.append(
            HeldOutTrial(
                str(trial.trial_id),
                frames,
                times,
                label=label,
                group=None if group is None else str(group),
            )
        )
    if not trials:
        raise SlipkitError(
            f"none of the held-out trials of run {run.path} has events in the rebuilt "
            f"dataset {dataset.name!r}"
        )
    return trials


def _deploy_davis(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any]
) -> Deployment:
    """``DavisRelease``: event frames in, the area filter as the ``davis_areas`` op.

    Frame = one ``frame_s`` event frame of the ``events`` stream as counts per pixel,
    shape ``(2, height_px, width_px)`` (positive, negative), window 1, hop 1, at
    ``1 / frame_s`` Hz. One preprocessing step, ``davis_areas`` (the detector's
    opening, closing and 8-connected area filter in numpy: ONNX has no connected
    components), gives the filtered areas; the graph is the polarity rule on them
    (:class:`slipkit.families.davis.export.polarity.DavisAreaRule`). Before anything is written, the
    op's areas are checked to equal the detector's (``DavisPolarity.frames``) on
    every held-out frame. Slip class ``"1"``; debounce :func:`davis_debounce` (the
    run's chosen one).
    """
    from slipkit.families.davis.classifier import EventFrameClassifier
    from slipkit.families.davis.export.polarity import DavisAreaRule
    from slipkit.families.davis.onset import DavisOnset
    from slipkit.families.davis.polarity import DavisPolarity
    from slipkit.families.davis.task import DavisRelease

    assert isinstance(task, DavisRelease)
    det = run.model
    if isinstance(det, EventFrameClassifier):  # the learned one: features in the graph
        return _deploy_davis_events(task, run, dataset, options)
    if type(det) is DavisOnset:  # the same areas, the onset rule's graph
        return deploy_davis_onset(task, run, dataset, options)
    if type(det) is not DavisPolarity:
        raise SlipkitError(
            f"run {run.path}: only the DavisPolarity and DavisOnset rules (their area "
            f"filter is the runtime's davis_areas op) and the EventFrameClassifier "
            f"deploy on DAVIS; the run's model is {type(det).__name__}"
        )
    return deploy_area_rule(task, run, dataset, options, DavisAreaRule().fit())


def deploy_area_rule(
    task: Task,
    run: Run,
    dataset: Dataset,
    options: Mapping[str, Any],
    rule: Any,
) -> Deployment:
    """A rule on the filtered areas (``rule``: the graph's estimator on ``(pos, neg)``)
    behind the ``davis_areas`` op, the op checked against the run's detector."""
    from slipkit.families.davis.task import DavisRelease

    assert isinstance(task, DavisRelease)
    det = run.model
    frame_s, h, w = float(det.frame_s), int(det.height_px), int(det.width_px)
    step = {
        "op": "davis_areas",
        "opening_px": int(det.opening_px),
        "opening_shape": str(det.opening_shape),
        "closing_px": int(det.closing_px),
        "min_area_px": int(det.min_area_px),
    }
    pipeline = Pipeline([step], (1, 2, h, w), "manifest.json")

    def check(trial: Any, ev: NDArray[np.float64], frames: NDArray[Any]) -> None:
        # Parity of the op with the training-side detector, frame by frame.
        want = det.frames(ev)[["pos_area_px", "neg_area_px"]].to_numpy(np.float64)
        got = np.stack([pipeline(f[None])[0].copy() for f in frames])
        bad = np.flatnonzero((want != got).any(axis=1))
        if len(bad):
            k = int(bad[0])
            raise SlipkitError(
                f"trial {trial.trial_id}, frame {k}: the runtime's davis_areas op gives "
                f"areas {got[k].tolist()} px but the detector {want[k].tolist()} px "
                f"({len(bad)} of {len(frames)} frames differ); no bundle written"
            )

    trials = _davis_held_out(task, run, dataset, frame_s, h, w, check)
    channels = [
        f"{p}_{r}_{c}" for p in ("pos", "neg") for r in range(h) for c in range(w)
    ]
    n_values = 2 * h * w
    return Deployment(
        frame={
            "streams": [task.stream],
            "channels": channels,
            "shape": [2, h, w],
            "window": 1,
            "hop": 1,
            "rate_hz": 1.0 / frame_s,
        },
        preprocessing=[step],
        export_options={},
        positive="1",
        debounce_k=davis_debounce(run, options),
        trials=trials,
        model=rule,
        max_replay_frames=max(1, DAVIS_REPLAY_BYTES // (8 * n_values)),
        notes=[
            f"event frames of {frame_s * 1e3:g} ms ({task.stream!r}): counts per pixel, "
            f"positive then negative, {h} x {w} px",
            "preprocessing davis_areas: opening, closing and 8-connected area filter "
            "(numpy; ONNX has no connected components), checked equal to the "
            "detector's areas on every held-out frame",
            "decision: slip when positive area > 0 and >= negative area (the graph)",
        ],
    )


def event_frame_deployment(
    task: Any,
    run: Run,
    dataset: Dataset,
    options: Mapping[str, Any],
    *,
    scores: Any,
    shape: tuple[float, int, int],
    own_features: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    source: str,
    atol: float,
    notes: list[str],
) -> Deployment:
    """A DAVIS deployment whose graph reads one whole event frame.

    Frame = one ``frame_s`` event frame as counts per pixel, ``(2, height_px,
    width_px)`` (``shape`` = (frame_s, height_px, width_px)), window 1, hop 1, at
    ``1 / frame_s`` Hz, no preprocessing; slip class ``"1"``, debounce
    :func:`davis_debounce`. Before anything is written, ``scores.features`` of every
    held-out frame must equal ``own_features`` of the events (the training side's,
    named ``source`` in the error; ``rtol`` 1e-12, ``atol``).
    """
    frame_s, h, w = shape

    def check(trial: Any, ev: NDArray[np.float64], frames: NDArray[Any]) -> None:
        want = own_features(ev)
        got = scores.features(frames)
        bad = np.flatnonzero(~np.isclose(want, got, rtol=1e-12, atol=atol).all(axis=1))
        if len(bad) or len(want) != len(got):
            k = int(bad[0]) if len(bad) else min(len(want), len(got))
            raise SlipkitError(
                f"trial {trial.trial_id}, frame {k}: the event frame's features differ "
                f"from {source} ({len(bad)} of {len(frames)} frames); no bundle written"
            )

    trials = _davis_held_out(task, run, dataset, frame_s, h, w, check)
    channels = [
        f"{p}_{r}_{c}" for p in ("pos", "neg") for r in range(h) for c in range(w)
    ]
    return Deployment(
        frame={
            "streams": [task.stream],
            "channels": channels,
            "shape": [2, h, w],
            "window": 1,
            "hop": 1,
            "rate_hz": 1.0 / frame_s,
        },
        preprocessing=[],
        export_options={},
        positive="1",
        debounce_k=davis_debounce(run, options),
        trials=trials,
        model=scores,
        max_replay_frames=max(1, DAVIS_REPLAY_BYTES // (8 * 2 * h * w)),
        notes=[
            f"event frames of {frame_s * 1e3:g} ms ({task.stream!r}): counts per pixel, "
            f"positive then negative, {h} x {w} px",
            *notes,
        ],
    )


def _deploy_davis_events(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any]
) -> Deployment:
    """``DavisRelease`` with the learned ``EventFrameClassifier``: the whole model in the graph.

    Frame = one ``frame_s`` (20 ms) event frame as counts per pixel, ``(2, height_px,
    width_px)``, window 1, hop 1, at ``1 / frame_s`` Hz, no preprocessing: the graph
    (:mod:`slipkit.families.davis.export.classifier`) computes the counts and areas and runs the scaler
    and logistic regression. The model checked and exported is
    :class:`slipkit.families.davis.export.classifier.EventFrameScores` (the classifier scoring event
    frames); before anything is written, its features of every held-out frame are
    checked equal to the classifier's own (``frame_features`` on the events). Slip
    class ``"1"`` (logit >= 0); debounce :func:`davis_debounce` (the run's chosen one).
    """
    from slipkit.families.davis.export.classifier import EventFrameScores
    from slipkit.families.davis.task import DavisRelease

    assert isinstance(task, DavisRelease)
    clf = run.model
    scores = EventFrameScores(classifier=clf).fit()
    return event_frame_deployment(
        task,
        run,
        dataset,
        options,
        scores=scores,
        shape=(float(clf.frame_s), int(clf.height_px), int(clf.width_px)),
        own_features=lambda ev: clf.frame_features(ev)[1],
        source="EventFrameClassifier.frame_features",
        atol=0.0,
        notes=[
            "the graph computes the event counts and areas (pixels that fired) per "
            "polarity and runs the scaler and logistic regression (no morphology)",
            "decision: slip when the logit >= 0 (probability >= 1/2)",
        ],
    )


def deploy_davis_onset(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any]
) -> Deployment:
    """A :class:`DavisOnset` run's deployment: event frames in, the whole rule in the graph.

    Frame = one ``frame_s`` event frame as counts per pixel, ``(2, height_px,
    width_px)``, window 1, hop 1, at ``1 / frame_s`` Hz, no preprocessing. Before
    anything is written, the features of every held-out frame are checked equal to the
    detector's own (``DavisOnset.frames`` on the events). Slip class ``"1"`` (score
    > 0); debounce :func:`davis_debounce` (the run's
    chosen one).
    """
    from slipkit.families.davis.export.onset import DavisOnsetScores

    det = run.model
    cols = ["pos_area_px", "neg_area_px", "curl"]
    return event_frame_deployment(
        task,
        run,
        dataset,
        options,
        scores=DavisOnsetScores(detector=det).fit(),
        shape=(float(det.frame_s), int(det.height_px), int(det.width_px)),
        own_features=lambda ev: det.frames(ev)[cols].to_numpy(np.float64),
        source="DavisOnset.frames",
        atol=1e-9,
        notes=[
            f"the graph keeps fired pixels with >= {det.min_neighbours} fired "
            "8-neighbours (Conv), sums their areas and the positive pixels' covariance",
            f"decision: slip when positive area >= {det.min_pos_px} px, negative <= "
            f"{det.neg_ratio:g} x positive and the positive pixels' curl < "
            f"{det.max_curl:g} (a straight one-sided loss of contact)",
        ],
    )


def _register_davis() -> None:
    from slipkit.families.davis.task import DavisRelease

    register_deployer(DavisRelease, _deploy_davis)


_register_davis()
