"""What the gripper-PC loop feeds each task's exported model: one deployer per task class.

``slipkit export`` knows how to turn a fitted estimator into a graph (the exporter
registry, :mod:`slipkit.export.registry`); this module knows, per *task*, what the
runtime (:mod:`slipkit.runtime`) must do around that graph so that it sees what the
estimator saw in training:

* the **frame**: stream(s), channel names, one frame's shape, frames per model call
  (``window``), frames between calls (``hop``) and the sensor rate (Hz);
* the **preprocessing** the graph does not hold, as steps of the runtime's closed op
  registry (:data:`slipkit.runtime.preprocessing.OPS`);
* the **exporter options** (e.g. the TacTip pin-velocity features inside the graph);
* which classes are **slip** (``positive``; a multi-class model: ``slip_classes``)
  and the **debounce** ``k``;
* the **held-out trials** of the run (its test split, rebuilt from the run's config
  with :func:`slipkit.train.data.training_dataset`), as raw frames + timestamps, with
  each trial's class and group so that the replay samples every class;
* what the saved model was **scored on** and whether it was **refit on all data**
  (then no trial is held out from it: the replay checks parity and latency only).

A deployer is registered per task class (:func:`register_deployer`; a subclass uses
its parent's, as :func:`slipkit.export.registry.exporter_for`). The model inputs for
parity are computed with the runtime's own :class:`~slipkit.runtime.preprocessing.Pipeline`
on the runtime's own windows (:func:`graph_inputs`), so the check covers exactly what
the loop will feed the graph.

Per task
--------
Family folders' deployers document their own tasks (e.g. TacTip's frame task in
``slipkit.families.tactip.deploy``).

``WindowClassification``
    Frame = one frame of ``task.stream`` (``task.channels``), window ``W`` and hop
    from the task (in frames). Mode ``raw``: no step; ``window``:
    ``subtract_first``; ``trial``: ``baseline_first`` with ``frames = 1``. Classes:
    the fitted model's ``classes_`` (any classifier the task fits). Slip classes: the
    export config's ``slip_classes`` (or ``positive``, one class), else ``slip`` when
    it is a class, else every class but the no-slip ones (``no_slip_classes``, e.g.
    DoS's ``t``, touch): a direction or slip-type model runs as a classifier whose
    decided class the runtime counts, and any slip class is a slip decision. With
    ``task.folds`` the run scored the model on its outer folds and then refit it on
    every trial: ``refit_on_all_data`` is true and no trial is held out from it.
    An analytic window rule (:func:`register_window_rule`, e.g. BioTac's in
    ``families/biotac/export/window_rules.py``) keeps no input width: the exporter gets
    the window (``n_frames``); a rule may name its bundle's slip classes (the DoS
    electrode energy decides touch against its one motion class, which is then the
    slip class).
``StreamDetection``
    Frame = one raw sample of ``task.stream`` (``task.channels``); window and hop are
    what the detector's graph needs (:class:`slipkit.export.detectors.DetectorGraph`,
    e.g. FSR: 10 samples every 5), no preprocessing (the detector's math is in the
    graph), except for a voltage-input FSR detector: one step, ``press_sign``, takes
    the stream's rest level from its first samples, as the batch detector does per
    recording, with the fitted polarity's sign or, for ``per_recording``, the wiring
    sign latched at its first press. Slip class ``1`` (the detector's positive
    class); parity is the detectors' own check on the held-out recordings (through
    that step).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

import slipkit.families as _families
from slipkit._registry import Registry
from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError
from slipkit.runtime.preprocessing import Pipeline
from slipkit.train.runs import Run
from slipkit.train.task import Task

log = logging.getLogger("slipkit.export")


@dataclass(frozen=True)
class HeldOutTrial:
    """One held-out trial as the runtime would receive it.

    Attributes
    ----------
    trial_id : str
        The trial.
    frames : ndarray of shape (n, *frame_shape)
        Raw frames, float64, in the manifest's channel order.
    timestamps : ndarray of shape (n,)
        Frame times, s (the trial's own clock).
    keep : ndarray of bool, shape (n,), or None
        Frames that are held out (a decision whose last frame is kept is used for
        parity); None: all of them.
    label : str or None
        The trial's class (the replay is stratified by it); None: unknown.
    group : str or None
        The trial's group, e.g. its object (the replay is stratified by it too).
    """

    trial_id: str
    frames: NDArray[np.float64]
    timestamps: NDArray[np.float64]
    keep: NDArray[np.bool_] | None = None
    label: str | None = None
    group: str | None = None


@dataclass
class Deployment:
    """Everything a bundle needs besides the graph, for one run.

    Attributes
    ----------
    frame : dict
        The manifest's ``frame`` object (streams, channels, shape, window, hop, rate_hz).
    preprocessing : list of dict
        Runtime op steps (manifest ``preprocessing``).
    export_options : dict
        Keyword options for :func:`slipkit.export.registry.export`.
    positive : str or None
        The slip class (None: a regressor, see ``regression``); with
        ``slip_classes``, one of them (the one a binary threshold rule would use).
    debounce_k : int
        Consecutive slip decisions before slip is declared.
    trials : list of HeldOutTrial
        The run's held-out trials (parity and ``replay.npz``).
    held_out : bool
        False when the saved model saw every trial (k-fold runs refit on all).
    notes : list of str
        What the runtime does and why, for the manifest's description.
    regression : dict or None
        For regressors: ``{"column": int, "axis": str, "threshold": float}``, the
        score entry and threshold of the manifest's decision.
    model : estimator or None
        The estimator to export and check instead of the run's saved model (e.g. one
        estimator picked out of a per-material dict); None: the run's model.
    detector : bool
        An analytic stream detector: the graph
        (:class:`slipkit.export.detectors.DetectorGraph`) fixes ``window`` and
        ``hop``, and parity is :func:`slipkit.export.detectors.check_detector_parity`
        on the held-out recordings.
    slip_classes : list of str or None
        A multi-class model's slip classes (the argmax rule declares slip when the
        decided class is any of them); None: ``[positive]``.
    refit_on_all_data : bool
        The saved model was refit on every trial after scoring (k-fold runs).
    scored_on : str or None
        What the run's metrics were computed on (None: the run's held-out test split).
    max_replay_frames : int or None
        A cap on the replay frames below the export config's (large frames, e.g.
        DAVIS event images); None: the config's alone.
    """

    frame: dict[str, Any]
    preprocessing: list[dict[str, Any]]
    export_options: dict[str, Any]
    positive: str | None
    debounce_k: int
    trials: list[HeldOutTrial]
    held_out: bool = True
    notes: list[str] = field(default_factory=list)
    regression: dict[str, Any] | None = None
    detector: bool = False
    model: Any = None
    slip_classes: list[str] | None = None
    refit_on_all_data: bool = False
    scored_on: str | None = None
    max_replay_frames: int | None = None

    @property
    def frame_shape(self) -> tuple[int, ...]:
        """Shape of one frame."""
        return tuple(int(s) for s in self.frame["shape"])

    def replay_trials(self, max_frames: int | None = None) -> list[HeldOutTrial]:
        """Whole held-out trials for ``replay.npz``: every class and group, within ``max_frames``.

        The trials are ranked round-robin over the classes (each class gives its
        next trial before any class gives another), and within a class
        round-robin over its groups (objects, or the FSR wiring), class ``c``
        starting at its ``c``-th group so that the first round already spans the
        groups; within a (class, group) the picks are spread over its trials
        (:func:`_spread`). So a bounded replay holds trials of every class and
        group from the whole test side, not the first trials, which a
        class-ordered dataset would fill with its first classes. In that rank, a
        trial that would exceed ``max_frames`` is passed over for a shorter one;
        then every class and every group that has no trial yet gets its shortest
        one, even past ``max_frames`` (at most one per class and group); the
        chosen trials keep their original order. When no whole trial fits, the
        first trial is cut to ``max_frames``. ``max_replay_frames`` caps
        ``max_frames`` and is never exceeded.
        """
        hard = self.max_replay_frames
        if hard is not None:
            max_frames = min(max_frames or hard, hard)
        if max_frames is None:
            return list(self.trials)
        order = _stratified_order(
            [tr.label for tr in self.trials], [tr.group for tr in self.trials]
        )
        chosen, total = [], 0
        for i in order:
            n = len(self.trials[i].frames)
            if total + n <= max_frames:
                chosen.append(i)
                total += n
        if not chosen and self.trials:
            tr = self.trials[0]
            return [
                HeldOutTrial(
                    tr.trial_id,
                    tr.frames[:max_frames],
                    tr.timestamps[:max_frames],
                    None if tr.keep is None else tr.keep[:max_frames],
                    tr.label,
                    tr.group,
                )
            ]
        for key in ("label", "group"):
            for value in dict.fromkeys(getattr(self.trials[i], key) for i in order):
                have = [i for i in order if getattr(self.trials[i], key) == value]
                if value is None or set(have) & set(chosen):
                    continue
                i = min(have, key=lambda j: len(self.trials[j].frames))
                n = len(self.trials[i].frames)
                if hard is None or total + n <= hard:
                    chosen.append(i)
                    total += n
        return [self.trials[i] for i in sorted(chosen)]

    def replay(
        self, max_frames: int | None = None, *, gap_periods: float = 1.0
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The replay trials (:meth:`replay_trials`) end to end: frames and timestamps (s).

        Each trial's clock is shifted to start ``gap_periods`` frame periods after the
        previous trial's last frame: 1 (the default) joins them seamlessly; more than
        the loop's ``max_gap_periods`` (1.5) leaves a gap at every trial boundary, so
        a stateful bundle's loop starts each trial from zero state, as its parity
        check and the batch detector do.
        """
        period = 1.0 / float(self.frame["rate_hz"])
        step = float(gap_periods) * period
        frames, times, start = [], [], 0.0
        for tr in self.replay_trials(max_frames):
            t = tr.timestamps - tr.timestamps[0] + start
            frames.append(tr.frames)
            times.append(t)
            start = float(t[-1]) + step if len(t) else start
        f = np.concatenate(frames) if frames else np.zeros((0, *self.frame_shape))
        ts = np.concatenate(times) if times else np.zeros(0)
        return f, ts


def _spread(n: int) -> list[int]:
    """``range(n)`` reordered so that every prefix is spread over it (0, n/2, n/4, 3n/4, ...).

    The van der Corput order: positions sorted by the bit-reversed binary fraction
    of their index on the next power of two.
    """
    if n <= 1:
        return list(range(n))
    bits = (n - 1).bit_length()

    def reversed_bits(i: int) -> int:
        return int(f"{i:0{bits}b}"[::-1], 2)

    return [i for i in sorted(range(1 << bits), key=reversed_bits) if i < n]


def _round_robin(lists: Sequence[Sequence[int]]) -> list[int]:
    """The first item of every list, then every second item, ..."""
    longest = max((len(v) for v in lists), default=0)
    return [v[k] for k in range(longest) for v in lists if k < len(v)]


def _stratified_order(
    labels: Sequence[str | None], groups: Sequence[str | None]
) -> list[int]:
    """Indices ranked round-robin over labels, within a label over groups (rotated), spread within."""
    by_label: dict[str | None, dict[str | None, list[int]]] = {}
    for i, (label, group) in enumerate(zip(labels, groups, strict=True)):
        by_label.setdefault(label, {}).setdefault(group, []).append(i)
    group_names = list(dict.fromkeys(groups))
    per_label = []
    for c, by_group in enumerate(by_label.values()):
        # Rotate the group order by the label's rank: the first round spans groups.
        rank = sorted(
            by_group,
            key=lambda g: (group_names.index(g) - c) % max(len(group_names), 1),
        )
        per_label.append(
            _round_robin(
                [[by_group[g][j] for j in _spread(len(by_group[g]))] for g in rank]
            )
        )
    return _round_robin(per_label)


Deployer = Callable[[Task, Run, Dataset, Mapping[str, Any]], Deployment]

_DEPLOYERS: Registry[type, Deployer] = Registry(
    "deployer", error=SlipkitError, n_args=4, key_type=type
)


def register_deployer(cls: type, fn: Deployer, *, overwrite: bool = False) -> None:
    """Register ``fn(task, run, dataset, options) -> Deployment`` for task class ``cls``."""
    _DEPLOYERS.register(cls, fn, overwrite=overwrite)


#: how the window deployer treats an analytic window rule's model, by estimator class: the
#: rule's slip classes (``fn(model) -> list of str or None``; None: the default choice)
_WINDOW_RULES: Registry[type, Callable[[Any], list[str] | None]] = Registry(
    "window rule", error=SlipkitError, n_args=1, key_type=type
)


def register_window_rule(
    cls: type, slip_classes: Callable[[Any], list[str] | None] = lambda model: None
) -> None:
    """Register estimator class ``cls`` as an analytic window rule: the window deployer
    passes its exporter the window length (``n_frames``: the rule keeps no input width)
    and takes the bundle's slip classes from ``slip_classes(model)`` unless the export
    config names them."""
    _WINDOW_RULES.register(cls, slip_classes)


def deployer_for(task: Task) -> Deployer:
    """The deployer of ``task``'s class or its nearest registered base (SlipkitError if none).

    Family folders' deployers (``slipkit.families.PLUGIN_MODULES["deployers"]``) register
    on the first lookup."""
    _families.load_plugins("deployers")
    found = _DEPLOYERS.for_class(type(task))
    if found is not None:
        return found
    known = ", ".join(sorted(c.__name__ for c in _DEPLOYERS))
    raise SlipkitError(
        f"slipkit export does not know how to deploy task {type(task).__name__} "
        f"(deployable tasks: {known})"
    )


def deployment(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any] | None = None
) -> Deployment:
    """The :class:`Deployment` of ``run`` (its task rebuilt, its dataset re-made)."""
    return deployer_for(task)(task, run, dataset, dict(options or {}))


# -- windows and graph inputs, as the runtime loop makes them -----------------------


def decision_ends(n_frames: int, window: int, hop: int) -> NDArray[np.intp]:
    """Indices of the frames on which the loop decides: ``window - 1 + j * hop``."""
    if n_frames < window:
        return np.zeros(0, dtype=np.intp)
    return np.arange(window - 1, n_frames, hop, dtype=np.intp)


def graph_inputs(
    frames: NDArray[np.floating],
    frame: Mapping[str, Any],
    preprocessing: Sequence[Mapping[str, Any]],
    input_shape: Sequence[int],
    *,
    skip_nonfinite: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """The graph input of every loop decision on one stream, and the frame it ends on.

    Runs the runtime's :class:`~slipkit.runtime.preprocessing.Pipeline` (freshly
    compiled, so stateful steps start from the stream's first frame) over the
    windows the loop forms, in order. With ``skip_nonfinite``, windows holding a
    bad value are skipped (no preprocessing call), as
    :class:`slipkit.runtime.StreamLoop` skips them: an infinity, or a NaN unless
    every stream reads NaN as "missing" (``NAN_IS_MISSING_STREAMS``: TacTip pins);
    without it every window is kept (parity).

    Parameters
    ----------
    frames : ndarray of shape (n, *frame.shape)
        One stream's frames.
    frame : mapping
        The manifest ``frame`` object.
    preprocessing : sequence of mapping
        The manifest ``preprocessing`` steps.
    input_shape : sequence of int
        The graph input's shape without the batch axis.

    Returns
    -------
    inputs : ndarray of shape (n_decisions, *input_shape), float64
    ends : ndarray of int
        Frame index that completes each decision's window.
    """
    window = int(frame["window"])
    shape = tuple(int(s) for s in frame["shape"])
    x = np.asarray(frames, dtype=np.float64).reshape(len(frames), *shape)
    pipeline = Pipeline(list(preprocessing), (window, *shape), "manifest.json")
    ends = loop_ends(x, frame, skip_nonfinite=skip_nonfinite)
    out = np.empty((len(ends), *(int(s) for s in input_shape)))
    for i, end in enumerate(ends):
        out[i] = np.reshape(pipeline(x[end - window + 1 : end + 1]), out.shape[1:])
    return out, ends


def loop_ends(
    frames: NDArray[np.floating], frame: Mapping[str, Any], *, skip_nonfinite: bool
) -> NDArray[np.intp]:
    """The frames of one stream on which the loop decides (:func:`decision_ends`);
    with ``skip_nonfinite``, without the windows holding a frame the loop flags (an
    infinity, or a NaN unless every stream reads NaN as "missing")."""
    window, hop = int(frame["window"]), int(frame.get("hop", 1))
    ends = decision_ends(len(frames), window, hop)
    if not skip_nonfinite:
        return ends
    from slipkit.runtime.loop import NAN_IS_MISSING_STREAMS

    flat = np.asarray(frames, dtype=np.float64).reshape(len(frames), -1)
    streams = set(frame.get("streams") or ())
    if streams and streams <= NAN_IS_MISSING_STREAMS:
        ok = ~np.isinf(flat).any(axis=1)  # NaN means "missing" (TacTip pins)
    else:
        ok = np.isfinite(flat).all(axis=1)
    bad = np.concatenate([[0], np.cumsum(~ok)])
    return ends[bad[ends + 1] - bad[ends + 1 - window] == 0]


def held_out_inputs(
    dep: Deployment, input_shape: Sequence[int], *, max_calls: int | None = None
) -> NDArray[np.float64]:
    """Graph inputs of every held-out decision, each trial its own stream (as in training)."""
    parts = []
    for tr in dep.trials:
        x, ends = graph_inputs(tr.frames, dep.frame, dep.preprocessing, input_shape)
        if tr.keep is not None:
            x = x[tr.keep[ends]]
        parts.append(x)
    out = (
        np.concatenate(parts)
        if parts
        else np.zeros((0, *(int(s) for s in input_shape)))
    )
    if max_calls is None or len(out) <= max_calls:
        return out
    # Evenly spaced over every held-out call (not the first ones: a dataset in class
    # order would leave the last classes unchecked).
    return out[np.linspace(0, len(out) - 1, max_calls).round().astype(np.intp)]


def slip_decisions(
    scores: NDArray[np.floating], decision: Mapping[str, Any], threshold: float | None
) -> NDArray[np.bool_]:
    """Per-call slip decisions of the manifest rule (as :class:`slipkit.runtime.StreamLoop`).

    ``scores`` has one row per call (the flattened score output); ``argmax``: slip
    when the largest entry is one of ``decision.slip_classes`` (else ``positive``).
    """
    s = np.asarray(scores, dtype=np.float64).reshape(len(scores), -1)
    classes = decision.get("classes")
    positive = decision.get("positive")
    if decision["rule"] == "argmax":
        assert classes is not None
        slip = decision.get("slip_classes") or [positive]
        cols = [list(classes).index(c) for c in slip]
        return np.isin(np.argmax(s, axis=1), cols)
    col = s[:, int(decision.get("column", 0))]
    thr = float(threshold if threshold is not None else 0.0)
    above = col > thr if decision.get("strict", False) else col >= thr
    slip_above = classes is None or positive == classes[1]
    return np.asarray(above == slip_above)


# -- helpers shared by the deployers --------------------------------------------------


def run_metrics(run: Run) -> dict[str, Any]:
    """The run's ``metrics.json`` ({} when absent)."""
    path = Path(run.path) / "metrics.json"
    if not path.is_file():
        return {}
    loaded: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return loaded


def _rate(
    dataset: Dataset, stream: str, options: Mapping[str, Any] | None = None
) -> float:
    """The stream's own ``rate_hz``; without one, ``options["fallback_rate_hz"]``.

    ``slipkit export`` passes the sensor family's nominal rate (``configs/deploy``)
    as the fallback and records in the manifest which of the two the frame uses.
    """
    if stream not in dataset.streams:
        raise SlipkitError(
            f"dataset {dataset.name!r} has no stream {stream!r}; streams: {sorted(dataset.streams)}"
        )
    rate = dataset.streams[stream].rate_hz
    if rate is None:
        fallback = (options or {}).get("fallback_rate_hz")
        if fallback is None:
            raise SlipkitError(f"stream {stream!r} has no frame rate: cannot deploy it")
        log.warning(
            "stream %r has no rate_hz: the frame uses the sensor default %g Hz",
            stream,
            float(fallback),
        )
        return float(fallback)
    return float(rate)


def trial_classes(
    dataset: Dataset,
    trials: Sequence[HeldOutTrial],
    label: str | None,
    group: str | None,
) -> list[HeldOutTrial]:
    """``trials`` with each one's class (column ``label``) and group (``group``) filled in."""
    table = dataset.trials.set_index(dataset.trials["trial_id"].astype(str))

    def value(tid: str, col: str | None) -> str | None:
        if col is None or col not in table.columns:
            return None
        v = table.at[tid, col]
        return None if v is None or (isinstance(v, float) and np.isnan(v)) else str(v)

    return [
        HeldOutTrial(
            t.trial_id,
            t.frames,
            t.timestamps,
            t.keep,
            value(t.trial_id, label),
            value(t.trial_id, group),
        )
        for t in trials
    ]


#: Class names that mean "no slip" (the default slip classes are the others).
NO_SLIP_CLASSES = ("t", "touch", "static", "no_slip", "noslip", "stable", "none")


def choose_slip_classes(
    classes: Sequence[str], options: Mapping[str, Any]
) -> list[str]:
    """The slip classes of a classifier with ``classes`` (the export options first).

    ``options["slip_classes"]`` (a list) or ``options["positive"]`` (one class) when
    given; else ``["slip"]`` when it is a class; else every class not in
    ``options["no_slip_classes"]`` (default :data:`NO_SLIP_CLASSES`), e.g. every
    direction of slip against DoS's ``t`` (touch), or both of linear / rotational.
    """
    classes = [str(c) for c in classes]
    given = options.get("slip_classes")
    if given is None and options.get("positive") is not None:
        given = [options["positive"]]
    if given is not None:
        if isinstance(given, str) or not isinstance(given, Sequence):
            raise SlipkitError(
                f"slip_classes must be a list of class names; got {given!r}"
            )
        chosen = [str(c) for c in given]
        unknown = [c for c in chosen if c not in classes]
        if unknown or not chosen or len(set(chosen)) != len(chosen):
            raise SlipkitError(
                f"slip_classes {chosen} must be distinct classes of the model "
                f"{classes}" + (f"; not classes: {unknown}" if unknown else "")
            )
        return chosen
    if "slip" in classes:
        return ["slip"]
    no_slip = options.get("no_slip_classes")
    no_slip = NO_SLIP_CLASSES if no_slip is None else [str(c) for c in no_slip]
    chosen = [c for c in classes if c not in set(no_slip)]
    if not chosen:
        raise SlipkitError(
            f"every class of the model {classes} is a no-slip class "
            f"({list(no_slip)}); give slip_classes=[...]"
        )
    return chosen


def trial_frames(
    dataset: Dataset, trial_ids: Sequence[str], stream: str, channels: Sequence[str]
) -> list[HeldOutTrial]:
    """Frames of ``channels`` of ``stream`` for each of ``trial_ids``, in time order."""
    wanted = set(map(str, trial_ids))
    out = []
    for trial in dataset.subset([t for t in dataset.trial_ids if str(t) in wanted]):
        table = trial.streams[stream].sort_values("t", kind="stable")
        out.append(
            HeldOutTrial(
                str(trial.trial_id),
                table[list(channels)].to_numpy(dtype=np.float64),
                table["t"].to_numpy(dtype=np.float64),
            )
        )
    if not out:
        raise SlipkitError(
            f"none of the held-out trials {sorted(wanted)[:5]} is in the rebuilt dataset "
            f"{dataset.name!r}: was the run trained on other data?"
        )
    return out


def _frame(
    streams: Sequence[str],
    channels: Sequence[str],
    window: int,
    hop: int,
    rate: float,
) -> dict[str, Any]:
    return {
        "streams": list(streams),
        "channels": list(map(str, channels)),
        "shape": [len(channels)],
        "window": int(window),
        "hop": int(hop),
        "rate_hz": float(rate),
    }


# -- window classification ----------------------------------------------------------------


def _deploy_windows(
    task: Task, run: Run, dataset: Dataset, options: Mapping[str, Any]
) -> Deployment:
    from slipkit.train.tasks.slip_type import WindowClassification

    assert isinstance(task, WindowClassification)
    stream = task.stream
    rate = _rate(dataset, stream, options)
    spec = dataset.streams[stream]
    channels = list(spec.channels) if task.channels is None else list(task.channels)
    width = task.frames(task.window, dataset)
    hop = task.frames(task.hop, dataset)
    seed = int(run.config.get("seed", 0))
    metrics = run_metrics(run)
    folds = metrics.get("split", {}).get("test") or [
        te for _, te in task.splits(dataset, seed)
    ]
    test_ids = [str(t) for fold in folds for t in fold]
    held_out = len(folds) <= 1
    by = f"leave-{task.group}s-out" if task.split == "group" else "stratified by class"
    scored_on = (
        f"held-out test split of {len(test_ids)} trials ({task.split} split)"
        if held_out
        else f"{len(folds)}-fold {by} CV (outer folds), before the refit"
    )
    steps: list[dict[str, Any]]
    if task.mode == "raw":
        steps = []
    elif task.mode == "window":
        steps = [{"op": "subtract_first"}]
    elif task.mode == "trial":
        steps = [{"op": "baseline_first", "frames": 1, "hop": hop}]
    else:
        raise SlipkitError(
            f"task.mode {task.mode!r} is a control (each window replaced by the trial's "
            "first frame), not a deployable model"
        )
    # Any classifier the task fits (a network, a scikit-learn pipeline) has classes_.
    model_classes = [str(c) for c in getattr(run.model, "classes_", [])]
    if not model_classes:
        raise SlipkitError(
            f"run {run.path}: the saved {type(run.model).__name__} has no classes_ "
            "(not a fitted classifier)"
        )
    # An analytic window rule may decide fewer classes than classes_ (the DoS electrode
    # energy: touch against its one motion class): its slip classes unless the config
    # names others.
    rule = _WINDOW_RULES.for_class(type(run.model))
    rule_slip = None if rule is None else rule(run.model)
    if rule_slip is not None and not (
        options.get("slip_classes") or options.get("positive")
    ):
        slip = rule_slip
    else:
        slip = choose_slip_classes(model_classes, options)
    # The one class a binary threshold rule names: the configured one, else the
    # last slip class in classes_ order (the former default, the last class).
    positive = str(options.get("positive") or slip[-1])
    trials = trial_classes(
        dataset,
        trial_frames(dataset, test_ids, stream, channels),
        task.label,
        task.group if task.group in dataset.trials.columns else None,
    )
    return Deployment(
        frame=_frame([stream], channels, width, hop, rate),
        preprocessing=steps,
        # the analytic window rules keep no input width: their exporters take n_frames
        export_options={} if rule is None else {"n_frames": int(width)},
        positive=positive,
        debounce_k=int(options.get("debounce_k") or 1),
        trials=trials,
        held_out=held_out,
        slip_classes=slip,
        refit_on_all_data=not held_out,
        scored_on=scored_on,
        notes=[
            f"windows of {width} frames of {stream!r} ({len(channels)} channels), "
            f"flattened frame-major, mode {task.mode}, every {hop} frames",
            f"classes {model_classes} ({task.label}); slip when the decided class is "
            f"one of {slip}",
        ],
    )


# -- analytic stream detectors ------------------------------------------------------------


def _register_builtin() -> None:
    from slipkit.train.tasks.detection import StreamDetection
    from slipkit.train.tasks.slip_type import WindowClassification

    register_deployer(WindowClassification, _deploy_windows)
    from slipkit.export.deploy_detection import _deploy_detection

    register_deployer(StreamDetection, _deploy_detection)


_register_builtin()

__all__ = [
    "NO_SLIP_CLASSES",
    "Deployment",
    "HeldOutTrial",
    "choose_slip_classes",
    "decision_ends",
    "deployer_for",
    "deployment",
    "graph_inputs",
    "held_out_inputs",
    "register_deployer",
    "register_window_rule",
    "slip_decisions",
    "trial_classes",
]
