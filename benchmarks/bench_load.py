"""Deadlines under load: each family's bundle replayed with and without a competing CPU-bound process, real-time options off and on.

Run: ``.venv/bin/python benchmarks/bench_load.py [--frames 6000] [--core 0] [--keep DIR]
[--competitors all|N]
[--families tactip,fsr,biotac,sliptack,sliptack_full,davis]`` (``sliptack_inc`` on request).

1. Small bundles are made in a temp folder (or ``--keep``) with ``slipkit train``'s and
   ``slipkit export``'s own functions (:mod:`slipkit.closedloop.commands`: few trials,
   ``choose_session=false``): ``tactip`` (``experiment=tactip_svm``), ``fsr``
   (``fsr_roc``), ``biotac`` (``biotac_force``: the force regressor, slip where a force exceeds 0 N), ``sliptack`` (``sliptack_speed``,
   the 1000-sample window, speed >= 10 mm/s, the export's default
   ``regression.prepare=true``: the spectrum prepared on the frame before each
   decision by ``prepare.onnx``), ``sliptack_full`` (the same run with
   ``regression.prepare=false``: the whole-window graph on the decision frame),
   ``sliptack_inc`` (``regression.incremental=true``: the spectrum per hop by the
   runtime op ``sliding_spectrum``; not in the default list), ``davis``
   (``davis_release``, the ``davis_areas`` op).
2. Each bundle's ``replay.npz`` (its first ``--frames`` frames, unpaced) runs through
   ``slipkit-run`` in a fresh process under four conditions, in this order per bundle:
   ``quiet`` / ``load`` (busy-looping Python processes, one pinned to each core the
   benchmark may use - ``--competitors all``, the default - or to the first N of them
   starting at ``--core``; started before and killed after: with a free core left, a
   loop without options simply runs there and the load shows nothing) x ``options
   off`` (no real-time option) / ``on``
   (``--cpus <core> --realtime``: that core, SCHED_FIFO priority 10, GC frozen, one
   onnxruntime thread). With the options on, the loop shares its core with the
   competitor and outranks it.
3. Prints one row per bundle and condition: decisions, p50 / p99 / max latency (ms,
   frame arrival to decision) against the bundle's p99 budget (10 % of its frame
   period), decisions over the budget, the p99 of the frames that ran a prepare
   graph (``-`` without one), and whether both p99s are within it; then any
   real-time note (e.g. SCHED_FIFO not permitted).
4. With two or more SlipTack bundles: side by side in this process, rounds
   interleaved, the loop latency split into the preprocessing (numpy op, or the
   prepare graph on the frame before) and the graph call (:func:`sliptack_pair`).

The machine is shared (other jobs run on its cores too), so "quiet" is the machine as
it is; the difference between rows of one bundle is the point.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

#: name -> (training run name, train overrides, export overrides)
FAMILIES: dict[str, tuple[str, list[str], list[str]]] = {
    "tactip": ("tactip", ["experiment=tactip_svm", "dataset.n_trials=8"], []),
    "fsr": ("fsr", ["experiment=fsr_roc", "dataset.n_trials=8"], []),
    "biotac": ("biotac", ["experiment=biotac_force", "dataset.n_trials=4"], []),
    "sliptack": (
        "sliptack",
        ["experiment=sliptack_speed", "dataset.n_trials=6"],
        ["regression.threshold=10.0", "regression.prepare=true"],
    ),
    "sliptack_full": (
        "sliptack",
        ["experiment=sliptack_speed", "dataset.n_trials=6"],
        ["regression.threshold=10.0", "regression.prepare=false"],
    ),
    "davis": ("davis", ["experiment=davis_release", "dataset.n_trials=6"], []),
    "sliptack_inc": (
        "sliptack",
        ["experiment=sliptack_speed", "dataset.n_trials=6"],
        ["regression.threshold=10.0", "regression.incremental=true"],
    ),
}
#: The families run without --families.
DEFAULT_FAMILIES = ("tactip", "fsr", "biotac", "sliptack", "sliptack_full", "davis")

BUSY = "import os, sys; os.sched_setaffinity(0, {int(sys.argv[1])})\nwhile True: pass"


def build(root: Path, names: list[str]) -> dict[str, Path]:
    """Train (once per run name) and export each family's bundle under ``root``."""
    from slipkit.closedloop.commands import export_bundle, train_run

    runs: dict[str, Path] = {}
    out: dict[str, Path] = {}
    for name in names:
        run_name, train_over, export_over = FAMILIES[name]
        bundle = root / "bundles" / name
        if bundle.exists():
            out[name] = bundle
            continue
        if run_name not in runs:
            run_dir = root / "runs" / run_name
            if not run_dir.exists():
                run_dir.parent.mkdir(parents=True, exist_ok=True)
                t0 = time.perf_counter()
                spec = {
                    "experiment": train_over[0].split("=", 1)[1],
                    "overrides": train_over[2:],
                }
                n = int(train_over[1].split("=", 1)[1])
                train_run(spec, n, 0, run_dir)
                print(
                    f"trained {run_name} in {time.perf_counter() - t0:.0f} s",
                    flush=True,
                )
            runs[run_name] = run_dir
        bundle.parent.mkdir(parents=True, exist_ok=True)
        export_bundle(
            runs[run_name], bundle, 1, ["replay_max_frames=20000", *export_over]
        )
        out[name] = bundle
    return out


def competitor_cores(core: int, competitors: str) -> list[int]:
    """The cores the load's busy processes are pinned to: ``core`` first, then the others."""
    allowed = sorted(os.sched_getaffinity(0))
    if core not in allowed:
        raise SystemExit(f"--core {core}: not one of this process's cores {allowed}")
    order = [core] + [c for c in allowed if c != core]
    if competitors == "all":
        return order
    try:
        n = int(competitors)
    except ValueError:
        raise SystemExit(
            f"--competitors: 'all' or a count; got {competitors!r}"
        ) from None
    if not 1 <= n <= len(order):
        raise SystemExit(f"--competitors: 1..{len(order)} or 'all'; got {n}")
    return order[:n]


def run_one(
    bundle: Path,
    frames: int,
    core: int,
    load: bool,
    options: bool,
    busy_cores: list[int] | None = None,
) -> dict[str, Any]:
    """One ``slipkit-run`` replay in a fresh process; its --json summary."""
    with tempfile.TemporaryDirectory() as tmp:
        js = Path(tmp) / "out.json"
        cmd = [
            sys.executable,
            "-m",
            "slipkit.runtime.cli",
            str(bundle),
            "--frames",
            str(frames),
            "--json",
            str(js),
        ]
        if options:
            cmd += ["--cpus", str(core), "--realtime"]
        busy = []
        if load:
            busy = [
                subprocess.Popen([sys.executable, "-c", BUSY, str(c)])
                for c in (busy_cores or [core])
            ]
            time.sleep(0.3)  # let them reach their cores
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        finally:
            for b in busy:
                b.kill()
                b.wait()
        if proc.returncode not in (0, 1) or not js.exists():
            raise SystemExit(f"{' '.join(cmd)} failed: {proc.stderr.strip()}")
        out = json.loads(js.read_text())
        out["notes"] = [ln for ln in proc.stderr.splitlines() if "note:" in ln]
        return out


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--frames", type=int, default=6000)
    ap.add_argument("--core", type=int, default=0)
    ap.add_argument(
        "--keep", type=Path, help="make (or reuse) the bundles in this folder"
    )
    ap.add_argument("--families", default=",".join(DEFAULT_FAMILIES))
    ap.add_argument(
        "--competitors",
        default="all",
        help="busy processes under load: 'all' (one per core, default) or a count",
    )
    ap.add_argument(
        "--rounds", type=int, default=3, help="SlipTack side-by-side rounds (default 3)"
    )
    args = ap.parse_args()
    names = [n for n in args.families.split(",") if n]
    busy_cores = competitor_cores(args.core, args.competitors)
    unknown = sorted(set(names) - set(FAMILIES))
    if unknown:
        raise SystemExit(
            f"--families: unknown {unknown}; choose from {sorted(FAMILIES)}"
        )
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from slipkit import config_dir

    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            bundles = build(root, names)
        GlobalHydra.instance().clear()
        print(
            f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; under load one "
            f"busy process on each of cores {busy_cores}; --cpus {args.core} with the "
            f"options; {args.frames} frames per run, unpaced; ms"
        )
        head = (
            f"| {'bundle':13s} | budget | load  | options | decisions | p50    | p99    "
            f"| max    | over budget | prepare p99 | p99 within |"
        )
        print(head)
        print("|" + "|".join("-" * (len(c)) for c in head.split("|")[1:-1]) + "|")
        notes: set[str] = set()
        for name in names:
            for load in (False, True):
                for options in (False, True):
                    s = run_one(
                        bundles[name], args.frames, args.core, load, options, busy_cores
                    )
                    lat = s["latency_ms"] or {}
                    notes.update(s["notes"])
                    prep = (s.get("prepare") or {}).get("latency_ms")
                    prep_p99 = "-" if prep is None else f"{prep['p99']:.4f}"
                    print(
                        f"| {name:13s} | {s['budget_ms']['p99']:.4f} "
                        f"| {'load' if load else 'quiet':5s} | {'on' if options else 'off':7s} "
                        f"| {s['decisions']:9d} | {lat.get('p50', float('nan')):.4f} "
                        f"| {lat.get('p99', float('nan')):.4f} | {lat.get('max', float('nan')):.4f} "
                        f"| {s['over_budget']:11d} | {prep_p99:11s} "
                        f"| {'yes' if s['within_budget'] else 'NO':10s} |",
                        flush=True,
                    )
        for note in sorted(notes):
            print(note)
        pair = [n for n in ("sliptack", "sliptack_full", "sliptack_inc") if n in names]
        if len(pair) >= 2:
            sliptack_pair({n: bundles[n] for n in pair}, args.rounds)


def _pct(ns: list[int]) -> str:
    import numpy as np

    a = np.asarray(ns, dtype=np.float64) / 1e3
    return f"{np.percentile(a, 50):8.1f} {np.percentile(a, 99):8.1f}"


def sliptack_pair(paths: dict[str, Path], rounds: int) -> None:
    """SlipTack bundles side by side in this process (prepared, whole-window, incremental).

    Rounds interleaved (each bundle in turn, ``rounds`` times) over the same replay
    frames, numpy's OpenBLAS on one thread (as ``--pin-threads``); per decision: the
    loop (frame arrival -> decision), and its parts timed on the same windows: the
    preprocessing alone (the numpy op; for a prepared bundle its prepare graph on the
    window one frame earlier, the work of the frame before the decision) and the graph
    call alone (``session.run`` on the precomputed inputs). us, pooled over rounds.
    """
    import numpy as np

    from slipkit.runtime import ReplaySource, StreamLoop, load_bundle
    from slipkit.runtime.realtime import blas_threads

    blas_threads(1)  # as --pin-threads: numpy's BLAS on one thread
    loaded = {k: load_bundle(p) for k, p in paths.items()}
    rep = np.load(next(iter(paths.values())) / "replay.npz")
    frames, times = rep["frames"], rep["timestamps"]
    res: dict[str, dict[str, list[int]]] = {
        k: {"loop": [], "prep": [], "graph": []} for k in loaded
    }
    for _ in range(rounds):
        for key, b in loaded.items():
            loop = StreamLoop(b)
            r = loop.run(ReplaySource(frames, times))
            res[key]["loop"] += r.latency_ns.tolist()
            w, hop = b.manifest.frame.window, b.manifest.frame.hop
            (inp,) = b.manifest.inputs
            pipe = b.preprocessing
            for op in pipe.ops:
                getattr(op, "reset", lambda: None)()
            name, out = inp.name, b.manifest.decision.output
            tensor = b.manifest.prepare
            for end in range(w - 1, len(frames), hop):
                x = np.asarray(frames[end - w + 1 : end + 1], dtype=np.float64)
                t0 = time.perf_counter_ns()
                y = pipe(x)
                t1 = time.perf_counter_ns()
                feed = {name: np.asarray(y, dtype=np.float32).reshape(inp.shape)}
                if tensor is not None and b.prepare_session is not None:
                    # the window one frame earlier (its oldest row: a zero before the
                    # stream, dropped by the graph)
                    lo = max(end - w, 0)
                    prev = np.zeros((w, *x.shape[1:]), dtype=np.float32)
                    prev[w - (end - lo) :] = frames[lo:end]
                    t0 = time.perf_counter_ns()
                    part = b.prepare_session.run([tensor], {name: prev[None]})[0]
                    t1 = time.perf_counter_ns()
                    feed[tensor] = part
                t2 = time.perf_counter_ns()
                b.session.run([out], feed)
                t3 = time.perf_counter_ns()
                res[key]["prep"].append(t1 - t0)
                res[key]["graph"].append(t3 - t2)
    print(
        f"SlipTack side by side ({rounds} rounds interleaved, {len(frames)} replay "
        "frames; us, p50 p99; budget 100 us)"
    )
    print(f"{'bundle':13s} {'loop':>17s} {'prep (op/graph)':>17s} {'graph call':>17s}")
    for key, r in res.items():
        print(f"{key:13s} {_pct(r['loop'])} {_pct(r['prep'])} {_pct(r['graph'])}")


if __name__ == "__main__":
    main()
