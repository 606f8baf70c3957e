"""Cost of the runtime op ``press_sign`` (FSR per-recording polarity) per loop call.

Run: ``.venv/bin/python benchmarks/bench_press_sign.py [--calls 5000]``.

The op as a bundle compiles it (:class:`slipkit.runtime.preprocessing.Pipeline`) on the
two FSR graph windows: the paper's 10 samples and the confirmed variant's 845. Before
the latch (a stream at rest: every call looks at the window's block means) and after
it (one subtraction and a sign); median of ``--calls`` calls, microseconds.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from slipkit.runtime.preprocessing import Pipeline

STEP = {"op": "press_sign", "rest_frames": 10, "block": 5, "hop": 5, "delta": 0.2}


def _median_us(pipe: Pipeline, x: np.ndarray, calls: int) -> float:
    times = np.empty(calls)
    for i in range(calls):
        t0 = time.perf_counter_ns()
        pipe(x)
        times[i] = time.perf_counter_ns() - t0
    return float(np.median(times)) / 1e3


def main() -> None:
    """Print the op's median time per call before and after the latch."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=5000)
    args = ap.parse_args()
    print(f"{'window':>6s} {'before latch us':>16s} {'after latch us':>15s}")
    for w in (10, 845):
        pipe = Pipeline([STEP], (w, 1), "bench")
        rest = np.full((w, 1), 3.0)
        pipe(rest)  # the stream's first window: rest 3 V, no press
        before = _median_us(pipe, rest, args.calls)
        pressed = rest.copy()
        pressed[-5:] = 2.0  # the newest block 1 V below rest: latched, sign +1
        pipe(pressed)
        after = _median_us(pipe, pressed, args.calls)
        print(f"{w:6d} {before:16.2f} {after:15.2f}")


if __name__ == "__main__":
    main()
