"""Cost of the learned SlipTack speed graph (``spectral_gbr``), before and after sharing one DFT.

Run: ``.venv/bin/python benchmarks/bench_spectral_export.py [--run RUN] [--trials N]
[--blocks B] [--calls C] [--realtime] [--no-fd-run RUN2] [--paced N]``.

Without ``--run`` / ``--no-fd-run`` it first trains the comparison's ``spectral_gbr``
(the comparison's hard pull, ``N`` = 36 trials, seed 0,
``configs/model/sliptack_spectral_gbr.yaml``) with the ``f_d`` feature
(``model.f_d_feature=true``, the model before issue 16) and without it (the shipped
config) into temporary run folders, ~3 min each on a loaded 2-core machine (at 12
trials, the comparison's size, the validation scores 2 trials and both runs scored the
same there, MAE 34.71 mm/s). Then, from a run's ``"*"``
estimator (the one ``slipkit export`` deploys):

* **graphs** - ``export_spectral_speed(est, shared_dft=False)`` (before: the analytic
  ``f_d`` graph's own DFT and a second one for the features) and ``shared_dft=True``
  (after: both tapered windows through one two-GEMM DFT), and, as the floor, the
  analytic ``f_d`` nodes alone (``sliptack._frequency``: every graph above holds them);
* **inputs** - the float32 windows the runtime feeds at every call on the run's held-out
  trials (the export deployer's ``trials``, :func:`detector_windows`);
* **time** - batch-1 ``InferenceSession.run`` on one onnxruntime thread
  (:func:`onnx_session`), the graphs interleaved in blocks of ``C`` calls (``B``
  blocks) so that they share the machine's load; p50 / p99 per graph in us. With
  ``--realtime`` the timing runs as ``slipkit-run --realtime`` does (SCHED_FIFO where
  permitted, GC frozen; :mod:`slipkit.runtime.realtime`), else at normal priority;
* **as the loop calls it** - with ``--paced N``, also ``N`` calls per graph one ``hop``
  of frame periods apart (50 ms), spinning to each due time as the runtime loop does
  at 1 kHz, the graphs in turn, beside an empty graph (one ``ReduceMean``: the call
  alone). Back to back, each call finds the graph's code and data in cache; the loop
  calls the graph after ``hop - 1`` frames of other work, and ``slipkit compare`` /
  ``slipkit-run --check`` judge that paced latency against the budget;
* **same predictions** - max |speed| difference of each graph against
  ``SpectralSpeedRegressor.predict`` at the same calls, and before vs after (mm/s);
* **the model change** - the run without the ``f_d`` feature (``--no-fd-run``, trained
  on the same data with ``model.f_d_feature=false``): its graph timed in the same
  blocks (on its own held-out calls), and both runs' validation scores
  (``metrics.json``'s ``validation.overall``: group CV by trial on the training half;
  the test half is not read).

Nothing is tuned on these numbers; the table is quoted in ``docs/export.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from onnx import helper

from slipkit import config_dir
from slipkit.export._graph import DOUBLE, FLOAT, GraphBuilder
from slipkit.export.detectors import detector_windows
from slipkit.export.parity import onnx_session
from slipkit.export.registry import ExportedGraph
from slipkit.families.sliptack.export.spectral import (
    export_spectral_speed,
    graph_speeds,
)
from slipkit.families.sliptack.export.speed import _frequency
from slipkit.runtime.realtime import RealtimeOptions, apply_realtime, frozen_gc


def _compose(name: str, overrides: list[str]) -> Any:
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    GlobalHydra.instance().clear()
    return cfg


def train(run_dir: Path, trials: int, f_d: bool) -> Path:
    """The comparison's spectral_gbr on the hard pull (``trials`` trials, seed 0), with
    or without the ``f_d`` feature."""
    from slipkit.train.commands import train_main

    train_main(
        _compose(
            "train",
            [
                "experiment=sliptack_speed",
                "~detector",
                "model=sliptack_spectral_gbr",
                "scene=sliptack_pull_hard",
                f"dataset.n_trials={trials}",
                f"model.f_d_feature={str(f_d).lower()}",
                f"run_dir={run_dir}",
            ],
        )
    )
    return run_dir


def held_out(run_dir: Path) -> tuple[Any, list[np.ndarray]]:
    """The deployed ``"*"`` estimator and the held-out trials' nib samples."""
    from slipkit.export.deploy import deployment
    from slipkit.train.commands import build
    from slipkit.train.data import training_dataset
    from slipkit.train.runs import read_run

    run = read_run(run_dir)
    dep = deployment(
        build(run.config.task, "task"),
        run,
        training_dataset(run.config),
        {"regression": {"threshold": 0.0}},
    )
    return dep.model.speed, [np.asarray(t.frames, np.float64) for t in dep.trials]


def _validation(run_dir: Path) -> dict[str, Any]:
    """The run's validation record (``metrics.json``; never its test half)."""
    return dict(json.loads((Path(run_dir) / "metrics.json").read_text())["validation"])


def fd_only(est: Any) -> ExportedGraph:
    """The analytic ``f_d`` nodes alone (the part every spectral_gbr graph holds)."""
    w = int(est.window)
    g = GraphBuilder("f_d_only", 17)
    x = g.op("Reshape", g.op("Cast", "window", to=DOUBLE), g.const([-1, w], np.int64))
    fd = _frequency(g, x, est.physics_, "float32")
    g.nodes.append(helper.make_node("Cast", [fd], ["score"], to=FLOAT))
    model = g.build(
        [helper.make_tensor_value_info("window", FLOAT, ["batch", w, 1])],
        [helper.make_tensor_value_info("score", FLOAT, ["batch"])],
        doc="f_d only",
    )
    return _window_graph(model, w, "f_d (Hz)")


def empty_graph(window: int) -> ExportedGraph:
    """One node (the window's mean): what any graph's call costs before its own work."""
    node = helper.make_node(
        "ReduceMean", ["window"], ["score"], axes=[1, 2], keepdims=0
    )
    model = helper.make_model(
        helper.make_graph(
            [node],
            "empty",
            [helper.make_tensor_value_info("window", FLOAT, ["batch", window, 1])],
            [helper.make_tensor_value_info("score", FLOAT, ["batch"])],
        ),
        opset_imports=[helper.make_opsetid("", 17)],
    )
    return _window_graph(model, window, "mean")


def _window_graph(model: Any, window: int, meaning: str) -> ExportedGraph:
    """A graph of one ``window`` input and one ``score`` output, as the bench times it."""
    return ExportedGraph(
        model=model,
        input_name="window",
        input_shape=("batch", window, 1),
        output_names=("score",),
        score_output="score",
        score_meaning=meaning,
        score_method="predict",
        opset=17,
    )


def paced_times(
    sessions: dict[str, Any], inputs: dict[str, np.ndarray], calls: int, period_s: float
) -> dict[str, list[int]]:
    """``calls`` batch-1 calls per graph, the graphs in turn, each call ``period_s``
    after the previous one (spinning to its due time): every call follows ``period_s``
    without onnxruntime work, as a decision follows ``hop`` frames in the loop."""
    times: dict[str, list[int]] = {k: [] for k in sessions}
    due = time.perf_counter()
    for j in range(calls):
        for k, sess in sessions.items():
            due += period_s
            while time.perf_counter() < due:
                pass
            feed = {"window": inputs[k][j % len(inputs[k])][None]}
            t0 = time.perf_counter_ns()
            sess.run(["score"], feed)
            times[k].append(time.perf_counter_ns() - t0)
    return times


def main() -> None:
    """Train (or read) the run, build the graphs, time them interleaved, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, default=None)
    ap.add_argument("--trials", type=int, default=36)
    ap.add_argument("--blocks", type=int, default=40)
    ap.add_argument("--calls", type=int, default=250)
    ap.add_argument("--realtime", action="store_true")
    ap.add_argument("--no-fd-run", type=Path, default=None)
    ap.add_argument("--paced", type=int, default=0, metavar="N")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = args.run or train(Path(tmp) / "run", args.trials, True)
        no_fd = args.no_fd_run or train(Path(tmp) / "no_fd", args.trials, False)
        est, trials = held_out(run_dir)
        est2, trials2 = held_out(no_fd)
        validation = {"with f_d": _validation(run_dir), "no f_d": _validation(no_fd)}
    if not getattr(est, "f_d_feature", True):
        raise SystemExit(f"{run_dir}: its model has no f_d feature (--run)")
    if getattr(est2, "f_d_feature", True):
        raise SystemExit(f"{no_fd}: its model has the f_d feature (--no-fd-run)")
    graphs = {
        "before (two DFTs)": export_spectral_speed(est, shared_dft=False),
        "after (one shared DFT)": export_spectral_speed(est, shared_dft=True),
        "f_d nodes alone (floor)": fd_only(est),
    }
    wins, expected = [], []
    for x in trials:
        w, inst = detector_windows(graphs["after (one shared DFT)"], x)  # type: ignore[arg-type]
        wins.append(w)
        expected.append(est.predict(x)[inst])
    windows, ref = np.concatenate(wins), np.concatenate(expected)
    inputs = dict.fromkeys(graphs, windows)
    refs = dict.fromkeys(graphs, ref)
    key = "no f_d feature (model)"
    graphs[key] = export_spectral_speed(est2)
    w2 = [detector_windows(graphs[key], x) for x in trials2]  # type: ignore[arg-type]
    inputs[key] = np.concatenate([w for w, _ in w2])
    refs[key] = np.concatenate(
        [est2.predict(x)[i] for x, (_, i) in zip(trials2, w2, strict=True)]
    )
    sessions = {k: onnx_session(g) for k, g in graphs.items()}
    speeds = {
        k: graph_speeds(s.run(["score"], {"window": inputs[k]})[0])
        for k, s in sessions.items()
    }
    empty = "empty graph (the call)"
    if args.paced:
        graphs[empty] = empty_graph(int(est.window))
        sessions[empty] = onnx_session(graphs[empty])
        inputs[empty] = windows
    times: dict[str, list[int]] = {k: [] for k in graphs}
    opts = RealtimeOptions(
        priority="fifo" if args.realtime else "normal",
        freeze_gc=args.realtime,
        pin_threads=args.realtime,
    )
    state = apply_realtime(opts)
    with frozen_gc(opts.freeze_gc):
        for b in range(args.blocks):
            for k in graphs if b % 2 == 0 else reversed(list(graphs)):
                sess = sessions[k]
                win = inputs[k]
                for j in range(args.calls):
                    feed = {"window": win[(b * args.calls + j) % len(win)][None]}
                    t0 = time.perf_counter_ns()
                    sess.run(["score"], feed)
                    times[k].append(time.perf_counter_ns() - t0)
        paced = (
            paced_times(sessions, inputs, args.paced, est.hop / est.rate_hz)
            if args.paced
            else {}
        )
    if args.realtime:  # back to normal before printing
        apply_realtime(RealtimeOptions(priority="normal"))
        if hasattr(os, "sched_setscheduler") and "priority" in state.applied:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    print(
        f"spectral_gbr ({est.model}, window {est.window}, hop {est.hop}); "
        f"{len(windows)} held-out calls from {len(trials)} trials; "
        f"{args.blocks} x {args.calls} interleaved batch-1 calls per graph, 1 thread; "
        f"real-time: {state.applied or 'none'} {'; '.join(state.notes)}"
    )
    before = speeds["before (two DFTs)"]
    if args.paced:
        print(
            f"paced: {args.paced} calls per graph, one every {est.hop} frame periods "
            f"({est.hop / est.rate_hz * 1e3:g} ms), the {len(paced)} graphs in turn"
        )
    print(
        f"{'graph':26s} {'nodes':>5s} {'p50 us':>7s} {'p99 us':>7s} "
        + (f"{'paced p50':>9s} {'paced p99':>9s} " if args.paced else "")
        + f"{'max|speed - predict| mm/s':>26s}"
    )
    for k, g in graphs.items():
        t = np.asarray(times.get(k) or [np.nan]) / 1e3
        diff = (
            "-"
            if k.startswith(("f_d", "empty"))
            else f"{np.abs(speeds[k] - refs[k]).max():.2e}"
        )
        cols = ""
        if args.paced:
            tp = np.asarray(paced[k]) / 1e3
            cols = f"{np.percentile(tp, 50):9.1f} {np.percentile(tp, 99):9.1f} "
        print(
            f"{k:26s} {len(g.model.graph.node):5d} {np.percentile(t, 50):7.1f} "
            f"{np.percentile(t, 99):7.1f} {cols}{diff:>26s}"
        )
    after = speeds["after (one shared DFT)"]
    print(f"max |after - before| speed: {np.abs(after - before).max():.2e} mm/s")
    print("validation (group CV by trial, training half), overall:")
    for name, v in validation.items():
        o = v["overall"]
        print(
            f"  {name:9s} MAE {o['mae_mm_s']:.2f} mm/s, RMSE {o['rmse_mm_s']:.2f} "
            f"mm/s over {o['n_trials']:.0f} trials ({v['cv']}, k = {v['k']})"
        )


if __name__ == "__main__":
    main()
