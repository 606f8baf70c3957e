"""Cost of sending decisions out: :class:`StreamLoop` with and without a UDP sink.

Run: ``.venv/bin/python benchmarks/bench_sinks.py [--frames 3000] [--repeats 5]``.

The three test bundles of ``bench_runtime_loop.py`` (random weights, one intra-op
thread), each run through the loop with ``on_decision=None`` and with a
:class:`slipkit.runtime.sinks.UdpSink` sending to a :class:`DecisionReceiver` bound on
127.0.0.1 (not drained during the round: the kernel keeps or drops datagrams, the
sender never waits), rounds interleaved, median over rounds. Two numbers per case:

* latency p50: arrival -> decision as the loop records it. The sink runs after the
  clock stops, so this changes only through cache and allocator effects;
* wall per frame: the whole ``loop.run`` over the frames divided by their number,
  which includes the sink's pack + ``send`` on every decision.
"""

from __future__ import annotations

import os

# One core: pin BLAS/OpenMP pools before numpy loads.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from bench_runtime_loop import build_cases  # noqa: E402

from slipkit.runtime import ReplaySource, StreamLoop  # noqa: E402
from slipkit.runtime.sinks import DecisionReceiver, UdpSink  # noqa: E402


def measure(loop: StreamLoop, frames: np.ndarray) -> tuple[float, float]:
    """(latency p50 us, wall us per frame) of one pass."""
    loop.reset()
    src = ReplaySource(frames, np.arange(len(frames), dtype=np.float64))
    t0 = time.perf_counter_ns()
    lat = loop.run(src).latency_ns
    wall = (time.perf_counter_ns() - t0) / len(frames) / 1e3
    return float(np.percentile(lat, 50)) / 1e3, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(
        f"{args.frames} frames x {args.repeats} rounds (median), 1 intra-op thread; "
        "us per frame"
    )
    head = (
        "| graph | latency p50 none / udp | ratio | wall per frame none / udp | "
        "ratio | sink us per decision | sent | send errors (total) |"
    )
    rows = []
    with (
        tempfile.TemporaryDirectory() as tmp,
        DecisionReceiver(port=0, timeout_s=0.01) as rx,
        UdpSink("127.0.0.1", rx.port) as sink,
    ):
        for bundle, frames in build_cases(Path(tmp), args.frames):
            loops = {
                "none": StreamLoop(bundle),
                "udp": StreamLoop(bundle, on_decision=sink),
            }
            for lp in loops.values():
                measure(lp, frames)  # warm-up
            got: dict[str, list[tuple[float, float]]] = {k: [] for k in loops}
            for _ in range(args.repeats):
                for key, lp in loops.items():
                    got[key].append(measure(lp, frames))
                list(rx)  # drain between rounds (not timed)
            med = {k: np.median(np.asarray(v), axis=0) for k, v in got.items()}
            sent, errors = sink.n_sent - sum(r[2] for r in rows), sink.n_errors
            rows.append((bundle.manifest.name, med, sent, errors))
    print()
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for name, med, sent, errors in rows:
        (l0, w0), (l1, w1) = med["none"], med["udp"]
        print(
            f"| {name} | {l0:.1f} / {l1:.1f} | {l1 / l0:.2f}x | {w0:.1f} / {w1:.1f} | "
            f"{w1 / w0:.2f}x | {w1 - w0:.1f} | {sent} | {errors} |"
        )


if __name__ == "__main__":
    main()
