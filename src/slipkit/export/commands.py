"""``slipkit export run=<run folder> out=exports/<name>``: a checked ONNX bundle of a run.

Steps (``configs/export.yaml``): read the run (config, info, fitted model); rebuild
its task and its dataset (the dataset's fingerprint must match the run's); ask the
task's deployer (:mod:`slipkit.export.deploy`) what the runtime feeds; export the
estimator with the registry (:func:`slipkit.export.registry.export`); compute the
graph inputs of the held-out trials with the runtime's own preprocessing and check
parity (:func:`slipkit.export.parity.check_parity`: decisions agree on >= 99.9 % of
calls, every disagreement within ``score_eps`` of the threshold, max |score
difference| <= ``atol`` for networks and regressors) -- a failed check raises
:class:`~slipkit.errors.SlipkitError` and writes nothing; build the manifest in the
runtime's schema (:mod:`slipkit.runtime.bundle`): the class names and the slip
classes, the latency budget from the data's own frame rate (``frame.rate_hz``; the
sensor family's ``configs/deploy`` period only when the data has no rate, and
``budget_ms.source`` says which), and what the model was scored on and whether it
was refit on all data; pick the replay trials (every class and group of the test
side, bounded in frames: :meth:`~slipkit.export.deploy.Deployment.replay_trials`; a
gap between trials for a bundle with stream state); for such a bundle, run its loop
over every held-out trial as one stream with gaps against the model
(:func:`slipkit.export.parity.stream_parity`; a failure writes nothing);
measure the session options on the replay frames
(:func:`slipkit.runtime.choose_session`); write the bundle
atomically with :func:`slipkit.runtime.write_bundle` (which reloads it before the
final rename; ``sign_key``: with ``manifest.hmac``) with its model card
(``MODEL_CARD.md``, :mod:`slipkit.export.card`); print a summary and the bundle
folder last.
"""

from __future__ import annotations

import json
import logging
import math
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

import slipkit
import slipkit.families as _families
from slipkit._files import check_out_path
from slipkit.errors import SlipkitError

log = logging.getLogger("slipkit.export")


def deploy_config(cfg: DictConfig, sensor: str) -> dict[str, Any]:
    """The sensor's latency budget: ``cfg.deploy`` if chosen, else the ``configs/deploy`` file listing ``sensor``."""
    node = cfg.get("deploy")
    if node is None:
        for path in sorted((slipkit.config_dir() / "deploy").glob("*.yaml")):
            candidate = OmegaConf.load(path)
            assert isinstance(candidate, DictConfig)
            if sensor in list(candidate.get("sensors", [])):
                node = candidate
                break
    if node is None:
        raise SlipkitError(
            f"no configs/deploy/*.yaml lists sensor {sensor!r} under 'sensors'; "
            "choose one with deploy=<name>"
        )
    out = OmegaConf.to_container(node, resolve=True)
    assert isinstance(out, dict)
    period = float(out["frame_period_ms"])
    fraction = float(out.get("p99_fraction", 0.1))
    if period <= 0 or not 0 < fraction <= 1:
        raise SlipkitError(
            f"deploy: frame_period_ms must be > 0 and p99_fraction in (0, 1]; got {period}, {fraction}"
        )
    return {"frame_period": period, "p99": period * fraction}


def _finite(obj: Any) -> Any:
    """JSON-ready copy with NaN / inf replaced by None (the manifest is strict JSON)."""
    if isinstance(obj, Mapping):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _decision(
    graph: Any,
    positive: str | None,
    regression: Mapping[str, Any] | None,
    slip_classes: list[str] | None = None,
) -> tuple[dict[str, Any], float | None]:
    """The manifest ``decision`` object and top-level ``threshold``.

    The argmax rule gets ``slip_classes`` (default ``[positive]``); the threshold
    rule (two classes) names one slip class, ``positive``.
    """
    d = graph.decision()
    if d is None:
        if regression is None:
            raise SlipkitError(
                f"the exported graph has no classes and the task gives no regression "
                f"decision (score: {graph.score_meaning})"
            )
        return (
            {
                "output": graph.score_output,
                "rule": "threshold",
                "column": int(regression["column"]),
                "strict": True,
            },
            float(regression["threshold"]),
        )
    threshold = d.pop("threshold", None)
    classes = [str(c) for c in d.get("classes", [])]
    if positive not in classes:
        raise SlipkitError(
            f"positive {positive!r} is not one of the model's classes {classes}"
        )
    d["positive"] = positive
    if d["rule"] == "argmax":
        slip = list(slip_classes or [positive])
        unknown = [c for c in slip if c not in classes]
        if unknown:
            raise SlipkitError(
                f"slip_classes {unknown} are not classes of the model {classes}"
            )
        if positive not in slip:
            d["positive"] = slip[0]
        d["slip_classes"] = slip
    return d, None if threshold is None else float(threshold)


def _budget(cfg: DictConfig, dataset: Any, frame: Mapping[str, Any]) -> dict[str, Any]:
    """``budget_ms``: the frame period from the data's rate, else the sensor's default.

    The period is ``1000 / frame.rate_hz`` when every stream of the frame has its
    own ``rate_hz`` in the dataset (``source: data_rate_hz``); otherwise the sensor
    family's ``configs/deploy`` value (``source: sensor_default``). ``p99`` is the
    deploy config's ``p99_fraction`` of the period.
    """
    nominal = deploy_config(cfg, str(dataset.sensor))
    fraction = nominal["p99"] / nominal["frame_period"]
    streams = list(frame.get("streams") or [])
    if streams and all(
        s in dataset.streams and dataset.streams[s].rate_hz is not None for s in streams
    ):
        period = 1000.0 / float(frame["rate_hz"])
        return {
            "frame_period": period,
            "p99": period * fraction,
            "source": "data_rate_hz",
        }
    return {**nominal, "source": "sensor_default"}


def _parity_error(report: Mapping[str, Any], name: str) -> SlipkitError:
    return SlipkitError(
        f"parity check failed for {name}: decisions agree on "
        f"{report['agreement'] * 100:.3f} % of {report['n_frames']} held-out calls "
        f"(need >= 99.9 %), {report['n_disagree']} disagree"
        f"{'' if report['disagreements_near_threshold'] else ' (some farther than score_eps ' + format(report['score_eps'], '.3g') + ' from the threshold)'}"
        f", max |score diff| {report['max_abs_diff']:.3g}"
        f"{'' if report.get('atol') is None else ' (atol ' + format(report['atol'], '.3g') + ')'}; "
        "no bundle written"
    )


def _detector_parity(
    detector: Any, graph: Any, dep: Any, score_eps: float | None
) -> dict[str, Any]:
    """The detectors' parity on the held-out recordings; the graph's window and hop become the frame's."""
    from slipkit.export.detectors import DetectorGraph, check_detector_parity

    if not isinstance(graph, DetectorGraph):
        raise SlipkitError(
            f"{type(detector).__name__} exported as {type(graph).__name__}, not a "
            "DetectorGraph: its window and hop are unknown"
        )
    dep.frame["window"], dep.frame["hop"] = int(graph.window), int(graph.hop)
    from slipkit.export.frame_gru import StepGraph, graph_parity

    if isinstance(graph, StepGraph):
        # A recurrent step graph: the loop itself, frame by frame, per recording.
        return graph_parity(
            detector,
            graph,
            [t.frames for t in dep.trials],
            rate_hz=float(dep.frame["rate_hz"]),
        )
    X = np.concatenate([t.frames for t in dep.trials])
    segments = np.concatenate(
        [np.full(len(t.frames), k) for k, t in enumerate(dep.trials)]
    )
    return dict(
        check_detector_parity(
            detector, graph, X, segments=segments, score_eps=score_eps
        )
    )


def _stream_parity(
    bundle: Path,
    model: Any,
    graph: Any,
    dep: Any,
    input_shape: list[int],
    report: Mapping[str, Any],
    par: Mapping[str, Any],
) -> dict[str, Any]:
    """:func:`~slipkit.export.parity.stream_parity` of the probe bundle over every
    held-out trial, against the detector's own scores or the estimator's on each
    trial's graph inputs (the runtime's preprocessing, fresh per trial)."""
    from slipkit.export.deploy import graph_inputs
    from slipkit.export.parity import estimator_score, stream_parity

    def detector_scores(k: int, ends: Any) -> Any:
        return model.decision_function(dep.trials[k].frames)[ends]

    def estimator_scores(k: int, ends: Any) -> Any:
        x, at = graph_inputs(
            dep.trials[k].frames,
            dep.frame,
            dep.preprocessing,
            input_shape,
            skip_nonfinite=True,
        )
        return estimator_score(model, graph, x[np.searchsorted(at, ends)])

    exact = bool(getattr(graph, "network", False)) or not report.get(
        "has_decisions", True
    )
    return stream_parity(
        bundle,
        [t.frames for t in dep.trials],
        detector_scores if dep.detector else estimator_scores,
        score_eps=report.get("score_eps"),
        atol=float(par.get("atol", 1e-4)) if exact else None,
    )


def _stream_parity_error(report: Mapping[str, Any], name: str) -> SlipkitError:
    calls = (
        ""
        if report["calls_match"]
        else "the loop did not decide on each trial's own window grid; "
    )
    return SlipkitError(
        f"stream parity failed for {name}: over the {report['recordings']} held-out "
        f"trials as one stream with gaps, {calls}the loop's decisions agree with the "
        f"model's on {report['agreement'] * 100:.3f} % of {report['n_frames']} calls "
        f"(need >= 99.9 %), {report['n_disagree']} disagree; no bundle written"
    )


def _replay_sample(
    dep: Any, chosen: list[Any], max_frames: int | None, gaps: bool
) -> str:
    """What the replay holds, for ``training.replay.note``."""
    n, total = len(chosen), len(dep.trials)
    what = (
        f"all {total} test-side trials"
        if n == total
        and all(
            len(c.frames) == len(t.frames)
            for c, t in zip(chosen, dep.trials, strict=False)
        )
        else f"{n} of the {total} test-side trials (replay_max_frames={max_frames}; "
        "every class and group has one)"
    )
    return what + (
        ", ten frame periods apart (a gap: each trial starts a new recording)"
        if gaps
        else ", one frame period apart"
    )


def export_main(cfg: DictConfig) -> Path:
    """Export the run ``cfg.run`` as a bundle; print the bundle folder last and return it."""
    from slipkit.export import export  # registers the built-in exporters
    from slipkit.export.deploy import deployment, held_out_inputs
    from slipkit.export.detectors import DetectorGraph
    from slipkit.export.frame_gru import StepGraph
    from slipkit.export.parity import STREAM_GAP_PERIODS, check_parity
    from slipkit.runtime import choose_session, load_bundle, write_bundle
    from slipkit.runtime.bundle import read_key
    from slipkit.runtime.preprocessing import Pipeline
    from slipkit.train.commands import build
    from slipkit.train.data import training_dataset
    from slipkit.train.runs import read_run

    run = read_run(Path(str(cfg.run)))
    out = (
        Path(str(cfg.out))
        if cfg.get("out")
        else Path(str(cfg.get("exports_dir", "exports"))) / run.path.name
    )
    # Before any work: an existing bundle only is replaced, never the run or its data.
    check_out_path(
        out,
        inputs={
            "run": run.path,
            "dataset.path": (run.config.get("dataset") or {}).get("path"),
        },
        kind="bundle",
        overwrite=bool(cfg.get("overwrite", False)),
    )
    key = (
        read_key(str(cfg.sign_key), "sign_key", bundles=(out,))
        if cfg.get("sign_key") is not None
        else None
    )
    name = str(cfg.get("name") or out.name)
    task = build(run.config.task, "task")
    dataset = training_dataset(run.config)
    want = run.info.get("dataset", {}).get("fingerprint")
    if want and dataset.fingerprint() != want:
        raise SlipkitError(
            f"{run.path}: the rebuilt training data has fingerprint "
            f"{dataset.fingerprint()[:12]}... but the run recorded {want[:12]}...; the "
            "held-out trials cannot be recovered (was the dataset folder changed?)"
        )
    # The sensor's nominal rate stands in for a stream without its own rate_hz.
    nominal = deploy_config(cfg, str(dataset.sensor))
    # debounce_k: null deploys the run's own choice (its operating point, chosen on
    # validation trials), else the task's
    debounce = cfg.get("debounce_k")
    if debounce is None:
        debounce = (run.metrics.get("operating_point") or {}).get("debounce_k")
    options = {
        "positive": cfg.get("positive"),
        "slip_classes": _names(cfg, "slip_classes"),
        "no_slip_classes": _names(cfg, "no_slip_classes"),
        "fallback_rate_hz": 1000.0 / nominal["frame_period"],
        "debounce_k": debounce,
        "regression": OmegaConf.to_container(cfg.regression, resolve=True)
        if cfg.get("regression") is not None
        else None,
    }
    dep = deployment(task, run, dataset, options)
    if debounce is not None:
        dep.debounce_k = int(debounce)
    model = run.model if dep.model is None else dep.model
    graph = export(model, opset=int(cfg.get("opset", 17)), **dep.export_options)
    input_shape = [int(s) for s in graph.input_shape[1:]]
    par: dict[str, Any] = dict(cfg.get("parity") or {})
    score_eps = None if par.get("score_eps") is None else float(par["score_eps"])
    if dep.detector:
        report = _detector_parity(model, graph, dep, score_eps)
    else:
        inputs = held_out_inputs(
            dep,
            input_shape,
            max_calls=None if par.get("max_calls") is None else int(par["max_calls"]),
        )
        report = check_parity(
            model,
            graph,
            inputs,
            score_eps=score_eps,
            atol=float(par.get("atol", 1e-4)),
        )
    if not report["passed"]:
        raise _parity_error(report, name)
    decision, threshold = _decision(
        graph, dep.positive, dep.regression, dep.slip_classes
    )
    budget = _budget(cfg, dataset, dep.frame)
    replay_max = (
        None if cfg.get("replay_max_frames") is None else int(cfg.replay_max_frames)
    )
    replay_trials = dep.replay_trials(replay_max)
    # A bundle with stream state (a recurrent state, or an op such as press_sign
    # that latches a level at the stream's start) reads a gap as a new recording
    # (docs/deploy.md, "Stream state"): its replay leaves one between trials, so
    # each trial starts fresh, as in training and in the parity check.
    stream_state = isinstance(graph, StepGraph) or bool(
        Pipeline(
            dep.preprocessing,
            (int(dep.frame["window"]), *dep.frame_shape),
            "manifest.json",
        ).stream_state
    )
    frames, times = dep.replay(
        replay_max, gap_periods=STREAM_GAP_PERIODS if stream_state else 1.0
    )
    replay_by_class: dict[str, int] = {}
    for tr in replay_trials:
        if tr.label is not None:
            replay_by_class[tr.label] = replay_by_class.get(tr.label, 0) + 1
    scored_on = dep.scored_on or "the run's held-out test split"
    replay_note = (
        (
            "held-out trials: the replay checks parity, decisions and latency on data the "
            "model never saw"
            if dep.held_out
            else "the saved model was refit on all data, these trials included: the "
            "replay checks parity and latency, not accuracy (accuracy: scored_on)"
        )
        + "; "
        + _replay_sample(dep, replay_trials, replay_max, stream_state)
    )
    import onnxruntime

    metrics = run.info.get("objective", {})
    # read_run checked these bytes against run.json (and the objective against them)
    m = run.metrics
    manifest: dict[str, Any] = {
        "name": name,
        "description": (
            f"{type(model).__name__} from run {run.path.name} "
            f"({type(task).__name__}, {dataset.sensor}); " + "; ".join(dep.notes)
        ),
        "frame": dep.frame,
        "preprocessing": dep.preprocessing,
        "inputs": [
            {
                "name": graph.input_name,
                "dtype": graph.input_dtype,
                "shape": [1, *input_shape],
            }
        ],
        # the output's dtype (float32 or float64) and shape: write_bundle reads them
        # from the graph
        "outputs": [{"name": graph.score_output}],
        "decision": decision,
        "threshold": threshold,
        # a recurrent graph's state, carried by the loop (docs/deploy.md)
        **({"state": list(graph.state)} if isinstance(graph, StepGraph) else {}),
        # a prepare graph run on the frame before each decision (docs/deploy.md)
        **(
            {"prepare": {"tensor": graph.prepare_tensor}}
            if isinstance(graph, DetectorGraph) and graph.prepare is not None
            else {}
        ),
        "debounce": {"k": int(dep.debounce_k)},
        "budget_ms": budget,
        "opset": int(graph.opset),
        "producer": {
            **{k: str(v) for k, v in graph.producers.items()},
            "onnxruntime": onnxruntime.__version__,
        },
        "training": _finite(
            {
                "data_fingerprint": str(
                    run.info.get("dataset", {}).get("fingerprint", "")
                ),
                "run": str(run.path),
                "experiment": str(run.info.get("name", "")),
                "task": str(run.info.get("task", "")),
                "model": str(run.info.get("model", "")),
                "objective": metrics,
                "metrics": {"test": m.get("test")},
                "held_out_trials": [t.trial_id for t in dep.trials],
                "held_out": dep.held_out,
                "refit_on_all_data": bool(dep.refit_on_all_data),
                "scored_on": scored_on,
                "replay": {
                    "trials": len(replay_trials),
                    "frames": len(frames),
                    "held_out": dep.held_out,
                    **({"by_class": replay_by_class} if replay_by_class else {}),
                    "note": replay_note,
                },
                "score": graph.score_meaning,
                "parity": report,
            }
        ),
    }
    if threshold is None:
        manifest.pop("threshold")
    model_bytes = graph.serialize()
    prepare_bytes = (
        graph.serialize_prepare()
        if isinstance(graph, DetectorGraph) and graph.prepare is not None
        else None
    )
    session_note = "defaults"
    choose = bool(cfg.get("choose_session", True))
    # a recurrent graph's parity already ran through the loop over a stream with gaps
    stream_check = stream_state and not isinstance(graph, StepGraph)
    stream_report: dict[str, Any] | None = None
    rows: list[dict[str, Any]] = []
    sess_cfg = cfg.get("session") or {}
    max_frames = int(sess_cfg.get("max_frames", 500))
    if choose or stream_check:
        with tempfile.TemporaryDirectory(prefix="slipkit-export-") as tmp:
            probe = write_bundle(
                Path(tmp) / "bundle",
                model_bytes,
                manifest,
                replay=(frames, times),
                prepare=prepare_bytes,
            )
            if stream_check:
                stream_report = _stream_parity(
                    probe, model, graph, dep, input_shape, report, par
                )
                if not stream_report["passed"]:
                    raise _stream_parity_error(stream_report, name)
                manifest["training"]["stream_parity"] = _finite(stream_report)
            if choose:
                rows = choose_session(
                    load_bundle(probe),
                    frames,
                    times,
                    rounds=int(sess_cfg.get("rounds", 3)),
                    max_frames=max_frames,
                )
        if rows:
            manifest["session"] = rows[0]["session"]
            session_note = (
                f"measured: {rows[0]['session']} (loop p50 {rows[0]['p50_ms'] * 1e3:.1f} us, "
                f"p99 {rows[0]['p99_ms'] * 1e3:.1f} us)"
            )
    card = _card(
        cfg,
        manifest,
        run,
        dataset,
        rows,
        model_bytes,
        min(len(frames), max_frames),
        regression=dep.regression,
    )
    write_bundle(
        out,
        model_bytes,
        manifest,
        replay=(frames, times),
        overwrite=bool(cfg.get("overwrite", False)),
        prepare=prepare_bytes,
        key=key,
        card=card,
    )
    print(
        f"{name}: {type(model).__name__} ({type(task).__name__}) -> ONNX opset "
        f"{graph.opset}, input {graph.input_name} {[1, *input_shape]}, "
        f"{len(dep.preprocessing)} preprocessing step(s)"
    )
    side = "held-out" if dep.held_out else "test-side (refit on all data: not held out)"
    print(
        f"  parity on {report['n_frames']} {side} calls: agreement "
        f"{report['agreement'] * 100:.2f} %, max |score diff| {report['max_abs_diff']:.3g}"
    )
    if stream_report is not None:
        print(
            f"  stream parity (the loop over the {stream_report['recordings']} "
            f"{side} trials as one stream, a gap between trials): agreement "
            f"{stream_report['agreement'] * 100:.2f} % of {stream_report['n_frames']} calls"
        )
    if decision.get("rule") == "argmax":
        print(
            f"  classes {decision['classes']}; slip classes {decision['slip_classes']}"
        )
    print(
        f"  scored on: {scored_on}; refit on all data: "
        f"{'yes' if dep.refit_on_all_data else 'no'}"
    )
    source = {
        "data_rate_hz": f"the data's {float(dep.frame['rate_hz']):g} Hz",
        "sensor_default": f"the {dataset.sensor} default (the data has no rate)",
    }[budget["source"]]
    print(
        f"  budget p99 <= {budget['p99']:.4g} ms (frame period {budget['frame_period']:.4g} ms, "
        f"from {source}); session {session_note}"
    )
    classes_note = (
        " (" + ", ".join(f"{c} {n}" for c, n in replay_by_class.items()) + ")"
        if replay_by_class
        else ""
    )
    print(
        f"  replay: {len(frames)} frames of {len(replay_trials)} of the "
        f"{len(dep.trials)} test-side trial(s){classes_note}; "
        + ("held out" if dep.held_out else "held_out: false (parity and latency only)")
    )
    if key is not None:
        print(f"  signed: manifest.hmac (HMAC-SHA256 under {cfg.sign_key})")
    print(out)
    return out


def _card(
    cfg: DictConfig,
    manifest: Mapping[str, Any],
    run: Any,
    dataset: Any,
    rows: list[dict[str, Any]],
    model_bytes: bytes,
    n_frames: int,
    *,
    regression: Mapping[str, Any] | None,
) -> str:
    """The bundle's ``MODEL_CARD.md`` (:func:`slipkit.export.card.model_card`)."""
    from slipkit._files import sha256_bytes
    from slipkit.export.card import model_card

    # a class's own slipkit_kind tag (as slipkit compare reads it), else its module
    cls = type(run.model)
    tag = getattr(cls, "slipkit_kind", None)
    kind = (
        str(tag)
        if tag in ("analytic", "learned")
        else "analytic"
        if _families.detector_module(cls.__module__)
        else "learned"
    )
    rounds = int((cfg.get("session") or {}).get("rounds", 3))
    latency = {**rows[0], "frames": n_frames, "rounds": rounds} if rows else None
    note = (
        f"at export, the loop over the first {n_frames} replay frames back to back, "
        f"median of {rounds} round(s), session {json.dumps(rows[0]['session'])}"
        if rows
        else "the export measured no latency (choose_session=false)"
        if not cfg.get("choose_session", True)
        else "the replay made no decision to time"
    )
    if cfg.get("debounce_k") is not None:
        debounce_from = f"set at export (debounce_k={cfg.debounce_k})"
    elif (run.metrics.get("operating_point") or {}).get("debounce_k") is not None:
        debounce_from = "the run's operating point"
    else:
        debounce_from = "the task's default (the run records no operating point)"
    return model_card(
        manifest,
        run,
        dataset,
        kind=kind,
        latency=latency,
        latency_note=note,
        debounce_from=debounce_from,
        model_sha256=sha256_bytes(model_bytes),
        threshold_from=None
        if regression is None or "threshold" not in regression
        else "set at export (regression.threshold)",
    )


def _names(cfg: DictConfig, key: str) -> list[str] | None:
    """A list-of-names option (``slip_classes=[n,e,s]``) as strings; None when unset."""
    value = cfg.get(key)
    if value is None:
        return None
    value = (
        OmegaConf.to_container(value, resolve=True)
        if OmegaConf.is_config(value)
        else value
    )
    if not isinstance(value, list) or not value:
        raise SlipkitError(
            f"{key} must be a non-empty list of class names, e.g. {key}=[n,e,s]; got {value!r}"
        )
    return [str(v) for v in value]


__all__ = ["deploy_config", "export_main"]
