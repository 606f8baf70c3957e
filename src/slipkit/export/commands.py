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
runtime's schema (:mod:`slipkit.runtime.bundle`); measure the session options on
the replay frames (:func:`slipkit.runtime.choose_session`); write the bundle
atomically with :func:`slipkit.runtime.write_bundle` (which reloads it before the
final rename); print a summary and the bundle folder last.
"""

from __future__ import annotations

import logging
import math
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

import slipkit
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
    graph: Any, positive: str | None, regression: Mapping[str, Any] | None
) -> tuple[dict[str, Any], float | None]:
    """The manifest ``decision`` object and top-level ``threshold``."""
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
    return d, None if threshold is None else float(threshold)


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
    X = np.concatenate([t.frames for t in dep.trials])
    segments = np.concatenate(
        [np.full(len(t.frames), k) for k, t in enumerate(dep.trials)]
    )
    return dict(
        check_detector_parity(
            detector, graph, X, segments=segments, score_eps=score_eps
        )
    )


def export_main(cfg: DictConfig) -> Path:
    """Export the run ``cfg.run`` as a bundle; print the bundle folder last and return it."""
    from slipkit.export import export  # registers the built-in exporters
    from slipkit.export import force as _force  # noqa: F401  (registers force exporters)
    from slipkit.export.deploy import deployment, held_out_inputs
    from slipkit.export.parity import check_parity
    from slipkit.runtime import choose_session, load_bundle, write_bundle
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
    options = {
        "positive": cfg.get("positive"),
        "debounce_k": cfg.get("debounce_k"),
        "regression": OmegaConf.to_container(cfg.regression, resolve=True)
        if cfg.get("regression") is not None
        else None,
    }
    dep = deployment(task, run, dataset, options)
    if cfg.get("debounce_k") is not None:
        dep.debounce_k = int(cfg.debounce_k)
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
    decision, threshold = _decision(graph, dep.positive, dep.regression)
    budget = deploy_config(cfg, str(dataset.sensor))
    stream_period = 1000.0 / float(dep.frame["rate_hz"])
    if stream_period < budget["frame_period"] - 1e-9:
        # A stream faster than the sensor's nominal frame (e.g. BioTac pac at 2.2 kHz
        # beside 300 Hz electrodes): the loop must keep up with this stream's samples.
        fraction = budget["p99"] / budget["frame_period"]
        budget = {"frame_period": stream_period, "p99": stream_period * fraction}
    import onnxruntime

    metrics = run.info.get("objective", {})
    from slipkit.export.deploy import run_metrics

    m = run_metrics(run)
    manifest: dict[str, Any] = {
        "name": name,
        "description": (
            f"{type(model).__name__} from run {run.path.name} "
            f"({type(task).__name__}, {dataset.sensor}); " + "; ".join(dep.notes)
        ),
        "frame": dep.frame,
        "preprocessing": dep.preprocessing,
        "inputs": [
            {"name": graph.input_name, "dtype": "float32", "shape": [1, *input_shape]}
        ],
        "outputs": [{"name": graph.score_output, "dtype": "float32"}],
        "decision": decision,
        "threshold": threshold,
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
                "score": graph.score_meaning,
                "parity": report,
            }
        ),
    }
    if threshold is None:
        manifest.pop("threshold")
    frames, times = dep.replay(
        None if cfg.get("replay_max_frames") is None else int(cfg.replay_max_frames)
    )
    model_bytes = graph.serialize()
    session_note = "defaults"
    if bool(cfg.get("choose_session", True)):
        sess_cfg = cfg.get("session") or {}
        with tempfile.TemporaryDirectory(prefix="slipkit-export-") as tmp:
            probe = write_bundle(
                Path(tmp) / "bundle", model_bytes, manifest, replay=(frames, times)
            )
            rows = choose_session(
                load_bundle(probe),
                frames,
                times,
                rounds=int(sess_cfg.get("rounds", 3)),
                max_frames=int(sess_cfg.get("max_frames", 500)),
            )
        if rows:
            manifest["session"] = rows[0]["session"]
            session_note = (
                f"measured: {rows[0]['session']} (loop p50 {rows[0]['p50_ms'] * 1e3:.1f} us, "
                f"p99 {rows[0]['p99_ms'] * 1e3:.1f} us)"
            )
    write_bundle(
        out,
        model_bytes,
        manifest,
        replay=(frames, times),
        overwrite=bool(cfg.get("overwrite", False)),
    )
    print(
        f"{name}: {type(model).__name__} ({type(task).__name__}) -> ONNX opset "
        f"{graph.opset}, input {graph.input_name} {[1, *input_shape]}, "
        f"{len(dep.preprocessing)} preprocessing step(s)"
    )
    print(
        f"  parity on {report['n_frames']} held-out calls: agreement "
        f"{report['agreement'] * 100:.2f} %, max |score diff| {report['max_abs_diff']:.3g}"
    )
    print(
        f"  budget p99 <= {budget['p99']:.4g} ms (frame period {budget['frame_period']:.4g} ms); "
        f"session {session_note}"
    )
    print(f"  replay: {len(frames)} frames of {len(dep.trials)} held-out trial(s)")
    print(out)
    return out


__all__ = ["deploy_config", "export_main"]
