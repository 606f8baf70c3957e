"""Where a short decision's p99 comes from on this machine: interruptions, node dispatch, a bundle's tail.

Run: ``.venv/bin/python benchmarks/bench_tail.py [--bundle DIR] [--core 0] [--seconds 2]
[--rounds 5]``.

Three measurements, printed one block each:

1. **Interruptions.** A loop pinned to ``--core`` that only reads
   ``time.perf_counter_ns()`` for ``--seconds`` s; every step longer than 5 us is an
   interruption of the loop (the guest kernel's timer tick, the host). Prints their
   rate, their size (p50 / p90 / max, us) and the median interval between them. A
   decision of ``d`` us is hit with a probability of about ``rate x d``: once that is
   above 1 % the hits are the decision's p99.
2. **Node dispatch.** Chains of 1, 20 and 60 ``Add`` nodes on 10 and 1000 float64
   values, one onnxruntime thread, p50 / p99 of 3000 calls (us): the cost of a node
   that does next to no arithmetic, which the ``bench_deploy.py`` floor (an Identity
   call plus the FLOPs) does not count.
3. **A bundle's tail** (with ``--bundle``): its ``replay.npz`` through ``StreamLoop``
   ``--rounds`` times in this process (GC frozen), the decisions' latency p50 / p90 /
   p98 / p99 / p99.5 (us), the share over 70 % of the budget and over the budget, and
   the expected interruption hit rate for a decision of its p50 (block 1's rate); for a
   bundle with a prepare graph its frames' percentiles too.

The machine is shared: run it when nothing else is, and read the rates, not single
numbers. No test asserts any of this (timings).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import time
from pathlib import Path

import numpy as np


def interruptions(core: int, seconds: float) -> tuple[float, np.ndarray, float]:
    """Clock-only loop on ``core``: (rate per s, sizes us, median interval ms)."""
    with contextlib.suppress(AttributeError, OSError):  # not Linux: any core
        os.sched_setaffinity(0, {core})
    clock = time.perf_counter_ns
    end = clock() + int(seconds * 1e9)
    prev = clock()
    at: list[int] = []
    size: list[int] = []
    while True:
        t = clock()
        if t - prev > 5000:
            at.append(t)
            size.append(t - prev)
        prev = t
        if t > end:
            break
    sizes = np.asarray(size, dtype=np.float64) / 1e3
    gaps = np.diff(np.asarray(at, dtype=np.float64)) / 1e6
    return len(sizes) / seconds, sizes, float(np.median(gaps)) if len(gaps) else 0.0


def node_chain(n: int, size: int) -> tuple[float, float]:
    """p50 / p99 (us) of one call of a chain of ``n`` float64 ``Add`` nodes on ``size`` values."""
    import onnxruntime as ort
    from onnx import TensorProto, helper

    nodes, prev = [], "x"
    for i in range(n):
        nodes.append(helper.make_node("Add", [prev, "c"], [f"y{i}"]))
        prev = f"y{i}"
    dt = TensorProto.DOUBLE
    graph = helper.make_graph(
        nodes,
        "chain",
        [helper.make_tensor_value_info("x", dt, [1, size])],
        [helper.make_tensor_value_info(prev, dt, [1, size])],
        [helper.make_tensor("c", dt, [1], [1.0])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    sess = ort.InferenceSession(
        model.SerializeToString(), so, providers=["CPUExecutionProvider"]
    )
    x = np.ones((1, size))
    times = []
    for _ in range(3000):
        t0 = time.perf_counter_ns()
        sess.run(None, {"x": x})
        times.append(time.perf_counter_ns() - t0)
    p50, p99 = np.percentile(np.asarray(times) / 1e3, [50, 99])
    return float(p50), float(p99)


def bundle_tail(path: Path, rounds: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Decision and prepare-frame latencies (us) over ``rounds`` replays; the p99 budget, us."""
    from slipkit.runtime import ReplaySource, StreamLoop, load_bundle

    bundle = load_bundle(path)
    rep = np.load(path / "replay.npz")
    loop = StreamLoop(bundle)
    lat: list[int] = []
    prep: list[int] = []
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        for _ in range(rounds):
            loop.reset()
            res = loop.run(ReplaySource(rep["frames"], rep["timestamps"]))
            lat += res.latency_ns.tolist()
            prep += res.prepare_latency_ns.tolist()
    finally:
        gc.enable()
        gc.unfreeze()
    budget_us = bundle.manifest.budget.p99_ms * 1e3
    return np.asarray(lat) / 1e3, np.asarray(prep) / 1e3, budget_us


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--bundle", type=Path, help="a bundle folder with replay.npz")
    ap.add_argument("--core", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    rate, sizes, interval = interruptions(args.core, args.seconds)
    print(
        f"interruptions of a clock-only loop on core {args.core} over {args.seconds:g} s: "
        f"{rate:.0f} per s (median interval {interval:.2f} ms); size us p50 "
        + (
            f"{np.percentile(sizes, 50):.1f}, p90 {np.percentile(sizes, 90):.1f}, "
            f"max {sizes.max():.1f}"
            if len(sizes)
            else "- (none)"
        )
    )
    print("node dispatch: chains of float64 Add nodes, one call, us p50 / p99")
    for n in (1, 20, 60):
        cells = []
        for size in (10, 1000):
            p50, p99 = node_chain(n, size)
            cells.append(f"{size} values {p50:.1f} / {p99:.1f}")
        print(f"  {n:2d} nodes: " + "; ".join(cells))
    if args.bundle is not None:
        lat, prep, budget = bundle_tail(args.bundle, args.rounds)
        pct = (50, 90, 98, 99, 99.5)
        q = np.percentile(lat, pct)
        print(
            f"{args.bundle.name}: {len(lat)} decisions over {args.rounds} replays, us "
            + ", ".join(f"p{p:g} {v:.1f}" for p, v in zip(pct, q, strict=True))
            + f"; over 70 % of the {budget:g} us budget {np.mean(lat > 0.7 * budget) * 100:.2f} %,"
            f" over it {np.mean(lat > budget) * 100:.2f} %; expected hit rate at p50: "
            f"{rate * q[0] * 1e-4:.2f} %"
        )
        if len(prep):
            qp = np.percentile(prep, pct)
            print(
                f"  prepare frames: {len(prep)}, us "
                + ", ".join(f"p{p:g} {v:.1f}" for p, v in zip(pct, qp, strict=True))
            )


if __name__ == "__main__":
    main()
