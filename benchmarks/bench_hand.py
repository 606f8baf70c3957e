"""A five-stream hand in one process against each bundle alone (issue 16).

Trains five small runs in a temporary folder (``train_main``), exports each with
``slipkit export`` (``export_main``: parity checked), and replays them (each bundle's
``replay.npz``, repeated to fill the run) through
:mod:`slipkit.runtime.hand` **paced at the sensors' own rates** (each frame handed over
at its timestamp on the wall clock, as the sensor would send it), so a frame that
comes due while another stream's model runs waits, and that wait is in its latency:

* thumb: BioTac electrodes (300 Hz), the slip-type window CNN;
* index: BioTac electrodes (300 Hz), the slip-type window MLP;
* middle: BioTac electrodes (300 Hz), the 3x10 force MLP;
* palm: FSR (2 kHz), the touch-and-slip detector;
* ring: TacTip pins (120 Hz), the RBF SVM with the pin features in the graph.

Each round runs every bundle alone (paced, then unpaced), then the five together in one
process: paced in ``loop`` mode (one thread, round-robin), paced in ``threads`` mode (one
thread per stream), unpaced in ``loop`` mode, and paced in ``loop`` mode under each of
:data:`RT_CONFIGS` (the real-time options of ``slipkit-run``: SCHED_FIFO priority 10
when permitted, the garbage collector frozen, one onnxruntime thread, ``--cpus 1``,
``--spin-us``, ``--busy-poll``; priority and affinity restored after each run), each
run ``--seconds`` of sensor time; the table gives, per stream, the median
over rounds of each run's p50 / p99 (us), the decisions over the stream's own p99
budget (summed over rounds, out of all decisions) and the ratio hand p99 / alone p99;
for the runs alone, also the time of ``StreamLoop.step`` itself on a deciding frame
(timed by a wrapper, which adds a fraction of a microsecond to those runs' latency).

    .venv/bin/python benchmarks/bench_hand.py [--seconds 3] [--rounds 3] [--keep DIR]

``--walk`` instead runs the docs' multi-sensor walk on the same bundles (docs/deploy.md,
"From the wheel to a running hand"): a ``DecisionReceiver`` on 127.0.0.1:9100,
``slipkit-run --stream`` with two UDP inputs (index, palm) and one paced replay (ring)
sending every decision to it, and two sensor bridges (``UdpSender``) sending the index
and palm replays at their own rates; it prints slipkit-run's output and what the
receiver got per stream index.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import platform  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

#: stream -> (train overrides, what it is)
HAND: dict[str, tuple[list[str], str]] = {
    "thumb": (
        [
            "experiment=biotac_slip_type",
            "~task.compare",
            "model=window_cnn",
            "dataset.n_trials=40",
            "task.sweep=[]",
            "task.first_frame_control=false",
            "task.dynamics=null",
            "model.max_epochs=20",
        ],
        "BioTac electrodes 300 Hz, slip-type window CNN",
    ),
    "index": (
        [
            "experiment=biotac_slip_type",
            "~task.compare",
            "dataset.n_trials=40",
            "task.sweep=[]",
            "task.first_frame_control=false",
            "task.dynamics=null",
            "model.max_epochs=20",
        ],
        "BioTac electrodes 300 Hz, slip-type window MLP",
    ),
    "middle": (
        [
            "experiment=biotac_force",
            "~task.compare",
            "dataset.n_trials=6",
            "scene.model.duration_s=20",
            "task.block_s=10",
        ],
        "BioTac electrodes 300 Hz, 3x10 force MLP",
    ),
    "palm": (["experiment=fsr_roc"], "FSR 2 kHz, touch-and-slip detector"),
    "ring": (
        ["experiment=tactip_svm"],
        "TacTip 120 Hz, RBF SVM (pin features in graph)",
    ),
}


def _compose(name: str, overrides: list[str]) -> Any:
    from hydra import compose, initialize_config_dir

    from slipkit import config_dir

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


def make_bundles(root: Path, names: list[str]) -> dict[str, Path]:
    """Train and export each stream's run under ``root`` (reused when already there)."""
    from slipkit.export.commands import export_main
    from slipkit.train.commands import train_main

    out = {}
    for name in names:
        overrides, _ = HAND[name]
        run_dir, bundle_dir = root / "runs" / name, root / "exports" / name
        if not (run_dir / "run.json").is_file():
            with contextlib.redirect_stdout(io.StringIO()):
                train_main(
                    _compose(
                        "train", [*overrides, f"run_dir={run_dir}", "overwrite=true"]
                    )
                )
        if not (bundle_dir / "manifest.json").is_file():
            with contextlib.redirect_stdout(io.StringIO()):
                export_main(
                    _compose(
                        "export",
                        [f"run={run_dir}", f"out={bundle_dir}", "overwrite=true"],
                    )
                )
        out[name] = bundle_dir
    return out


def tiled_replay(bundle: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The bundle's replay repeated to ``n`` frames, each copy one frame period after the last."""
    from slipkit.runtime import load_replay

    f = bundle.manifest.frame
    frames, times = load_replay(bundle.replay_path, f.shape, f.rate_hz)
    period = 1.0 / f.rate_hz
    span = float(times[-1] - times[0]) + period
    reps = -(-n // len(frames))
    idx = np.arange(reps * len(frames))[:n]
    copy, row = np.divmod(idx, len(frames))
    return frames[row], (times[row] - times[0]) + copy * span


def _timed_step(step: Any, into: list[int]) -> Any:
    """``step`` that appends its own duration (ns) to ``into`` when it made a decision."""
    clock = time.perf_counter_ns

    def timed(values: Any, timestamp: Any = None, arrival_ns: Any = None) -> Any:
        t0 = clock()
        out = step(values, timestamp, arrival_ns)
        if out is not None:
            into.append(clock() - t0)
        return out

    return timed


def run_once(
    bundles: dict[str, Path],
    names: list[str],
    mode: str,
    seconds: float,
    *,
    pace: bool = True,
    pin_threads: bool = False,
    **loop_kw: Any,
) -> dict[str, Any]:
    """Run ``names`` together (one name: alone); per stream: latency ns, budget ms.

    ``loop_kw`` goes to :func:`~slipkit.runtime.hand.run_streams` (``busy_poll``,
    ``spin_us``); ``pin_threads``: each session with one intra-op
    and one inter-op thread (``slipkit-run --pin-threads``).

    Also ``"_cpu"``: the process's CPU time over the run's wall time (1.0 = one core).
    """
    from slipkit.runtime import StreamLoop, load_bundle
    from slipkit.runtime.hand import HandStream, ReplayFeed, StreamBinding, run_streams
    from slipkit.runtime.realtime import RealtimeOptions, pinned_session

    streams = []
    step_ns: dict[str, list[int]] = {}
    for i, name in enumerate(names):
        binding = StreamBinding(name, bundles[name])
        bundle = load_bundle(bundles[name])
        if pin_threads:
            bundle = bundle.with_session(
                pinned_session(bundle.session_spec, RealtimeOptions(pin_threads=True))
            )
        n = max(int(seconds * bundle.manifest.frame.rate_hz), 1)
        frames, times = tiled_replay(bundle, n)
        source = ReplayFeed(frames, times, pace=pace)
        loop = StreamLoop(bundle)
        if len(names) == 1:  # alone: also time StreamLoop.step itself, per decision
            loop.step = _timed_step(loop.step, step_ns.setdefault(name, []))  # type: ignore[method-assign]
        streams.append(HandStream(i, binding, bundle, loop, source))
    cpu0, wall0 = time.process_time(), time.perf_counter()
    run_streams(streams, mode, start_delay_s=0.05, **loop_kw)
    cpu = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
    out: dict[str, Any] = {"_cpu": cpu}
    for s in streams:
        assert s.error is None, s.error
        assert s.result is not None
        out[s.name] = {
            "lat_ns": s.result.latency_ns,
            "budget_ms": s.bundle.manifest.budget.p99_ms,
            "frames": s.result.n_frames,
            "rate_hz": s.bundle.manifest.frame.rate_hz,
            "bundle": s.bundle.manifest.name,
            "step_ns": np.asarray(step_ns.get(s.name, []), dtype=np.int64),
        }
    return out


def run_realtime(
    bundles: dict[str, Path],
    names: list[str],
    seconds: float,
    *,
    cpus: tuple[int, ...] | None = None,
    priority: str = "fifo",
    **loop_kw: Any,
) -> tuple[dict[str, Any], list[str]]:
    """The hand in ``loop`` mode, paced, with ``slipkit-run --realtime``'s priority and GC.

    SCHED_FIFO (priority 10) on this thread and the garbage collector frozen, both
    restored after (:mod:`slipkit.runtime.realtime`); no ``--cpus`` (the benchmark does
    not take a core from the other jobs). Returns the run and the notes of what the OS
    refused.
    """
    from slipkit.runtime.realtime import RealtimeOptions, apply_realtime, frozen_gc

    before = os.sched_getscheduler(0), os.sched_getparam(0)
    affinity = os.sched_getaffinity(0)
    nice_before = os.getpriority(os.PRIO_PROCESS, 0)
    state = apply_realtime(
        RealtimeOptions(cpus=cpus, priority=priority, rt_priority=10)
    )
    try:
        with frozen_gc(True):
            out = run_once(bundles, names, "loop", seconds, **loop_kw)
    finally:
        if "priority" in state.applied:
            if priority == "nice":
                os.setpriority(os.PRIO_PROCESS, 0, nice_before)
            else:
                os.sched_setscheduler(0, before[0], before[1])
        if "cpus" in state.applied:
            os.sched_setaffinity(0, affinity)
    return out, list(state.notes)


#: The hand (loop mode, paced) under real-time options, side by side in one run: key ->
#: (the slipkit-run options it stands for, run_realtime keywords). The first is the
#: configuration the earlier benchmark reported (SCHED_FIFO and the GC only).
RT_CONFIGS: dict[str, tuple[str, dict[str, Any]]] = {
    "loop_rt": ("--priority fifo --freeze-gc", {}),
    "rt_pin": ("--realtime", {"pin_threads": True}),
    "rt_spin": (
        "--realtime --cpus 1 --spin-us 450",
        {"pin_threads": True, "spin_us": 450.0, "cpus": (1,)},
    ),
    "rt_bp": (
        "--realtime --cpus 1 --busy-poll",
        {"pin_threads": True, "busy_poll": True, "cpus": (1,)},
    ),
    "bp": (
        "--freeze-gc --pin-threads --cpus 1 --busy-poll",
        {"pin_threads": True, "busy_poll": True, "cpus": (1,), "priority": "normal"},
    ),
}


def _pct_us(lat_ns: np.ndarray) -> tuple[float, float]:
    if len(lat_ns) == 0:
        return float("nan"), float("nan")
    p50, p99 = np.percentile(lat_ns / 1e3, [50, 99])
    return float(p50), float(p99)


def walk(bundles: dict[str, Path]) -> None:
    """The docs' walk: receiver, slipkit-run --stream with UDP inputs, two sensor bridges."""
    import subprocess
    import sys
    import threading
    import time

    from slipkit.runtime import DecisionReceiver, UdpSender, load_bundle, load_replay

    run = Path(sys.executable).with_name("slipkit-run")
    got: list[Any] = []
    with DecisionReceiver("127.0.0.1", 9100, timeout_s=3.0) as rx:
        listener = threading.Thread(target=lambda: got.extend(rx))
        listener.start()
        cmd = [
            str(run),
            "--stream",
            f"index={bundles['index']}@udp:127.0.0.1:9001",
            "--stream",
            f"palm={bundles['palm']}@udp:127.0.0.1:9004",
            "--stream",
            f"ring={bundles['ring']}",
            "--pace",
            "--send",
            "127.0.0.1:9100",
            "--timeout",
            "1",
            "--check",
        ]
        print("$ " + " ".join(cmd))
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        time.sleep(1.0)  # the listener starts before the sensors

        def bridge(name: str, port: int) -> None:
            b = load_bundle(bundles[name])
            f = b.manifest.frame
            frames, ts = load_replay(b.replay_path, f.shape, f.rate_hz)
            with UdpSender("127.0.0.1", port) as tx:
                t0 = time.perf_counter()
                for i, (t, values) in enumerate(zip(ts.tolist(), frames, strict=True)):
                    lag = t - float(ts[0]) - (time.perf_counter() - t0)
                    if lag > 0:
                        time.sleep(lag)
                    tx.send(i, t, values)

        bridges = [
            threading.Thread(target=bridge, args=a)
            for a in (("index", 9001), ("palm", 9004))
        ]
        for t in bridges:
            t.start()
        for t in bridges:
            t.join()
        out, err = proc.communicate(timeout=120)
        listener.join()
    print(err.rstrip())
    print(out.rstrip())
    print(f"exit status {proc.returncode}")
    by: dict[int, int] = {}
    for d in got:
        by[d.stream] = by.get(d.stream, 0) + 1
    print(
        f"receiver: {len(got)} decisions; by stream index: {dict(sorted(by.items()))}"
    )
    if got:
        print(f"first: {got[0]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="sensor time per run, s")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument(
        "--keep", type=Path, default=None, help="keep runs and bundles here"
    )
    ap.add_argument("--walk", action="store_true", help="run the docs' walk instead")
    args = ap.parse_args()

    import onnxruntime as ort

    root = args.keep or Path(tempfile.mkdtemp(prefix="bench_hand-"))
    names = list(HAND)
    bundles = make_bundles(root, names)
    if args.walk:
        walk(bundles)
        return
    # Paced (the sensors' rates): alone, the hand in one loop, the hand in threads;
    # unpaced (as fast as taken): alone and the hand in one loop (compute only).
    configs = ["alone", "loop", "threads", *RT_CONFIGS, "alone_fast", "loop_fast"]
    rt_notes: list[str] = []
    # name -> config -> list of (p50, p99, over, decisions) per round
    acc: dict[str, dict[str, list[tuple[float, float, int, int]]]] = {
        n: {c: [] for c in configs} for n in names
    }
    cpu: dict[str, list[float]] = {"alone": [], "loop": [], "threads": []}
    # name -> config (alone, alone_fast) -> StreamLoop.step p50 per round, us
    steps: dict[str, dict[str, list[float]]] = {
        n: {"alone": [], "alone_fast": []} for n in names
    }
    meta: dict[str, dict[str, Any]] = {}
    for _ in range(args.rounds):
        runs: dict[str, dict[str, Any]] = {c: {} for c in configs}
        alone_cpu = 0.0
        for name in names:
            r = run_once(bundles, [name], "loop", args.seconds)
            alone_cpu += r.pop("_cpu")
            runs["alone"].update(r)
            r = run_once(bundles, [name], "loop", args.seconds, pace=False)
            r.pop("_cpu")
            runs["alone_fast"].update(r)
        cpu["alone"].append(alone_cpu)
        for c, mode, pace in (
            ("loop", "loop", True),
            ("threads", "threads", True),
            ("loop_fast", "loop", False),
        ):
            runs[c] = run_once(bundles, names, mode, args.seconds, pace=pace)
            used = runs[c].pop("_cpu")
            if c in cpu:
                cpu[c].append(used)
        for c, (_, kw) in RT_CONFIGS.items():
            runs[c], notes = run_realtime(bundles, names, args.seconds, **kw)
            cpu.setdefault(c, []).append(runs[c].pop("_cpu"))
            rt_notes = notes or rt_notes
        for c in configs:
            for name, r in runs[c].items():
                lat = r["lat_ns"]
                p50, p99 = _pct_us(lat)
                over = int(np.sum(lat / 1e6 > r["budget_ms"]))
                acc[name][c].append((p50, p99, over, len(lat)))
                if c in ("alone", "alone_fast"):
                    steps[name][c].append(float(np.percentile(r["step_ns"], 50)) / 1e3)
                meta[name] = r
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"onnxruntime {ort.__version__}, numpy {np.__version__}, {os.cpu_count()} CPUs "
        f"({platform.machine()}), load average {load:.1f}; {args.rounds} rounds x "
        f"{args.seconds:g} s of sensor time per run; us; median over rounds"
    )
    print()
    print("Paced at the sensors' rates:")
    print()
    print(
        "| stream | rate Hz | budget p99 | alone p50 / p99 | hand (loop) p50 / p99 "
        "| loop / alone p99 | hand (threads) p50 / p99 | threads / alone p99 "
        "| over budget alone / loop / threads (of decisions) | hand met (loop / threads) |"
    )
    print("|" + "---|" * 10)
    med: dict[str, dict[str, tuple[float, float, int, int]]] = {}
    rt_rows = []
    for name in names:
        med[name] = {
            c: (
                float(np.median([r[0] for r in acc[name][c]])),
                float(np.median([r[1] for r in acc[name][c]])),
                sum(r[2] for r in acc[name][c]),
                sum(r[3] for r in acc[name][c]),
            )
            for c in configs
        }
        m = meta[name]
        budget_us = m["budget_ms"] * 1e3
        a, lo, th = med[name]["alone"], med[name]["loop"], med[name]["threads"]
        print(
            f"| {name}: {HAND[name][1]} | {m['rate_hz']:g} | {budget_us:.0f} | "
            f"{a[0]:.1f} / {a[1]:.1f} | {lo[0]:.1f} / {lo[1]:.1f} | "
            f"{lo[1] / a[1]:.2f}x | {th[0]:.1f} / {th[1]:.1f} | {th[1] / a[1]:.2f}x | "
            f"{a[2]} / {lo[2]} / {th[2]} (of {a[3]}) | "
            f"{'yes' if lo[1] <= budget_us else 'no'} / "
            f"{'yes' if th[1] <= budget_us else 'no'} |"
        )
        cells = []
        for c in RT_CONFIGS:
            rt = med[name][c]
            met_rounds = sum(r[1] <= budget_us for r in acc[name][c])
            cells.append(
                f"{rt[0]:.1f} / {rt[1]:.1f} | {rt[2]} | "
                f"{'yes' if rt[1] <= budget_us else 'no'} "
                f"({met_rounds}/{len(acc[name][c])})"
            )
        rt_rows.append(
            f"| {name} | {budget_us:.0f} | {a[0]:.1f} / {a[1]:.1f} | "
            + " | ".join(cells)
            + " |"
        )
    print()
    print(
        "CPU time / wall time of the paced runs (1.0 = one core): five bundles alone "
        f"(summed) {np.median(cpu['alone']):.2f}, hand (loop) "
        f"{np.median(cpu['loop']):.2f}, hand (threads) {np.median(cpu['threads']):.2f}"
    )
    print()
    print(
        "Paced, the hand in loop mode with real-time options (fifo = SCHED_FIFO 10; "
        "restored after each run)"
        + (f"; NOT APPLIED: {'; '.join(rt_notes)}" if rt_notes else "")
        + "; columns p50 / p99 (median over rounds), over budget (summed, of the "
        "decisions above), met (median p99 within the budget; in how many rounds "
        "the p99 was):"
    )
    print()
    for i, (c, (opts, _)) in enumerate(RT_CONFIGS.items(), 1):
        print(f"{i}. `{opts}` (CPU time / wall {np.median(cpu[c]):.2f})")
    print()
    head = " | ".join(
        f"{i}. p50 / p99 | over | met" for i in range(1, len(RT_CONFIGS) + 1)
    )
    print(f"| stream | budget p99 | alone (normal) p50 / p99 | {head} |")
    print("|" + "---|" * (3 + 3 * len(RT_CONFIGS)))
    for row in rt_rows:
        print(row)
    print()
    print("Unpaced (frames as fast as the loop takes them: compute per frame only):")
    print()
    print(
        "| stream | alone p50 / p99 | hand (loop) p50 / p99 | loop / alone p50 "
        "| alone: StreamLoop.step p50, unpaced / paced |"
    )
    print("|" + "---|" * 5)
    for name in names:
        a, lo = med[name]["alone_fast"], med[name]["loop_fast"]
        st = steps[name]
        print(
            f"| {name} | {a[0]:.1f} / {a[1]:.1f} | {lo[0]:.1f} / {lo[1]:.1f} | "
            f"{lo[0] / a[0]:.2f}x | {np.median(st['alone_fast']):.1f} / "
            f"{np.median(st['alone']):.1f} |"
        )
    print()
    print(f"bundles: {root / 'exports'}")


if __name__ == "__main__":
    main()
