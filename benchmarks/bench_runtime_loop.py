"""Loop overhead of ``slipkit.runtime``: the full per-frame loop vs a bare ``session.run``.

Run: ``.venv/bin/python benchmarks/bench_runtime_loop.py [--frames 3000] [--repeats 5]``.

For three test graphs (built here with ``onnx.helper``, one intra-op thread), measured
side by side in one process, rounds interleaved, median over rounds:

* ``bare run``: ``session.run([score], {X: x})`` on precomputed model inputs (one
  call per frame, timed around the call alone);
* ``bare bind``: the same through a preallocated IOBinding (``run_with_iobinding``);
* ``loop run`` / ``loop bind``: :class:`slipkit.runtime.StreamLoop` on the raw frames,
  timed from frame arrival to debounced decision (ring buffer + numpy preprocessing +
  the call + rule + debounce), with either call path.

Graphs: ``fsr_linear`` (3 channels x window 4, standardize, linear score),
``biotac_mlp`` (24 channels x window 10, standardize, 240-64-1 tanh MLP) and
``tactip_rbf`` (127 pins = 254 channels, window 2, ``pin_velocity_features`` in numpy,
standardize, an RBF SVM of 1128 support vectors written as MatMul/Exp). The weights
are random: this measures time, not accuracy. Budgets: 10 % of the sensor's frame
period (FSR 0.5 ms, BioTac 3.3 ms, TacTip 8.3 ms, issue 6).
"""

from __future__ import annotations

import os

# One core: pin BLAS/OpenMP pools before numpy loads.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import onnx  # noqa: E402
import onnxruntime as ort  # noqa: E402
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from slipkit.runtime import (  # noqa: E402
    Bundle,
    ReplaySource,
    StreamLoop,
    load_bundle,
    write_bundle,
)

OPSET = 17


def _model(nodes: list[Any], inits: dict[str, np.ndarray], n_in: int) -> bytes:
    graph = helper.make_graph(
        nodes,
        "bench",
        [helper.make_tensor_value_info("X", TensorProto.FLOAT, [1, n_in])],
        [helper.make_tensor_value_info("score", TensorProto.FLOAT, [1, 1])],
        initializer=[
            numpy_helper.from_array(v.astype(np.float32), k) for k, v in inits.items()
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)])
    model.ir_version = 10  # onnxruntime 1.31 refuses onnx 1.23's default IR 14
    onnx.checker.check_model(model)
    return bytes(model.SerializeToString())


def linear_graph(rng: np.random.Generator, n_in: int) -> bytes:
    """score = X @ w + b."""
    nodes = [
        helper.make_node("MatMul", ["X", "W"], ["xw"]),
        helper.make_node("Add", ["xw", "B"], ["score"]),
    ]
    return _model(nodes, {"W": rng.normal(size=(n_in, 1)), "B": np.zeros((1, 1))}, n_in)


def mlp_graph(rng: np.random.Generator, n_in: int, hidden: int) -> bytes:
    """score = tanh(X @ W1 + b1) @ W2 + b2."""
    nodes = [
        helper.make_node("Gemm", ["X", "W1", "B1"], ["h"]),
        helper.make_node("Tanh", ["h"], ["a"]),
        helper.make_node("Gemm", ["a", "W2", "B2"], ["score"]),
    ]
    inits = {
        "W1": rng.normal(size=(n_in, hidden)) / np.sqrt(n_in),
        "B1": np.zeros(hidden),
        "W2": rng.normal(size=(hidden, 1)) / np.sqrt(hidden),
        "B2": np.zeros(1),
    }
    return _model(nodes, inits, n_in)


def rbf_graph(rng: np.random.Generator, n_in: int, n_sv: int, gamma: float) -> bytes:
    """score = sum_i a_i exp(-gamma |x - sv_i|^2) + b, as MatMul/Exp (no SVMClassifier op).

    ``-gamma |x - sv|^2 = 2 gamma x.sv - gamma |x|^2 - gamma |sv|^2``.
    """
    sv = rng.normal(size=(n_sv, n_in))
    nodes = [
        helper.make_node("MatMul", ["X", "SVT2G"], ["xs"]),
        helper.make_node("ReduceSumSquare", ["X"], ["xx"], axes=[1], keepdims=1),
        helper.make_node("Mul", ["xx", "G"], ["gxx"]),
        helper.make_node("Sub", ["xs", "gxx"], ["t1"]),
        helper.make_node("Sub", ["t1", "GSVN"], ["t2"]),
        helper.make_node("Exp", ["t2"], ["k"]),
        helper.make_node("MatMul", ["k", "ALPHA"], ["ka"]),
        helper.make_node("Add", ["ka", "B"], ["score"]),
    ]
    inits = {
        "SVT2G": 2 * gamma * sv.T,
        "G": np.array([gamma]),
        "GSVN": gamma * np.sum(sv**2, axis=1)[None, :],
        "ALPHA": rng.normal(size=(n_sv, 1)),
        "B": np.zeros((1, 1)),
    }
    return _model(nodes, inits, n_in)


def _manifest(
    name: str,
    channels: int,
    window: int,
    n_in: int,
    rate_hz: float,
    steps: list[dict[str, Any]],
) -> dict[str, Any]:
    period = 1000.0 / rate_hz
    return {
        "name": name,
        "frame": {
            "streams": ["bench"],
            "channels": [f"c{i}" for i in range(channels)],
            "shape": [channels],
            "window": window,
            "hop": 1,
            "rate_hz": rate_hz,
        },
        "preprocessing": steps,
        "inputs": [{"name": "X", "dtype": "float32", "shape": [1, n_in]}],
        "outputs": [{"name": "score", "dtype": "float32"}],
        "decision": {"output": "score", "rule": "threshold"},
        "threshold": 0.0,
        "debounce": {"k": 2},
        "budget_ms": {"frame_period": period, "p99": period / 10},
        "session": {"intra_op_num_threads": 1, "warmup": 50},
        "opset": OPSET,
        "producer": {"onnx": onnx.__version__, "onnxruntime": ort.__version__},
    }


def _replay(frames: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    return frames, np.arange(len(frames)) / rate_hz


def build_cases(root: Path, n_frames: int) -> list[tuple[Bundle, np.ndarray]]:
    """The three test bundles and their raw frames."""
    rng = np.random.default_rng(0)
    cases = []

    def std(n: int) -> dict[str, Any]:
        return {"op": "standardize", "mean": np.zeros(n), "scale": np.ones(n)}

    # FSR: 3 channels at 2 kHz (0.5 ms frame period), window 4.
    m = _manifest("fsr_linear", 3, 4, 12, 2000.0, [std(3)])
    x = rng.normal(size=(n_frames, 3))
    write_bundle(
        root / "fsr_linear", linear_graph(rng, 12), m, replay=_replay(x, 2000.0)
    )
    cases.append(("fsr_linear", x))
    # BioTac: 24 channels at 300 Hz (3.3 ms), window 10, MLP.
    m = _manifest("biotac_mlp", 24, 10, 240, 300.0, [std(24)])
    x = rng.normal(size=(n_frames, 24))
    write_bundle(
        root / "biotac_mlp", mlp_graph(rng, 240, 64), m, replay=_replay(x, 300.0)
    )
    cases.append(("biotac_mlp", x))
    # TacTip: 127 pins (x block, y block) at 120 Hz (8.3 ms), window 2, RBF SVM.
    steps = [{"op": "pin_velocity_features"}, std(254)]
    m = _manifest("tactip_rbf", 254, 2, 254, 120.0, steps)
    pins = np.cumsum(rng.normal(scale=0.05, size=(n_frames, 254)), axis=0)
    rbf = rbf_graph(rng, 254, 1128, 1.0 / 254)
    write_bundle(root / "tactip_rbf", rbf, m, replay=_replay(pins, 120.0))
    cases.append(("tactip_rbf", pins))
    return [(load_bundle(root / name), x) for name, x in cases]


def model_inputs(bundle: Bundle, frames: np.ndarray) -> list[np.ndarray]:
    """What the loop feeds the graph, precomputed, so the bare call times the call alone."""
    w = bundle.manifest.frame.window
    (inp,) = bundle.manifest.inputs
    assert inp.shape is not None
    out = []
    for i in range(w - 1, len(frames)):
        x = bundle.preprocessing(frames[i - w + 1 : i + 1])
        out.append(np.ascontiguousarray(x.reshape(inp.shape), dtype=np.float32))
    return out


def bare_run(bundle: Bundle, xs: list[np.ndarray]) -> np.ndarray:
    """Per-call ns of ``session.run([score], feed)``."""
    sess, name = bundle.session, bundle.manifest.inputs[0].name
    names = [bundle.manifest.decision.output]
    clock = time.perf_counter_ns
    lat = np.empty(len(xs), dtype=np.int64)
    for i, x in enumerate(xs):
        feed = {name: x}
        t0 = clock()
        sess.run(names, feed)
        lat[i] = clock() - t0
    return lat


def bare_bind(bundle: Bundle, xs: list[np.ndarray]) -> np.ndarray:
    """Per-call ns of ``run_with_iobinding`` with input and output bound once."""
    sess, name = bundle.session, bundle.manifest.inputs[0].name
    out_name = bundle.manifest.decision.output
    buf = np.empty_like(xs[0])
    out = np.empty_like(sess.run([out_name], {name: buf})[0])
    io = sess.io_binding()
    io.bind_ortvalue_input(name, ort.OrtValue.ortvalue_from_numpy(buf))
    io.bind_ortvalue_output(out_name, ort.OrtValue.ortvalue_from_numpy(out))
    clock = time.perf_counter_ns
    lat = np.empty(len(xs), dtype=np.int64)
    for i, x in enumerate(xs):
        buf[...] = x  # not timed: the bare call alone
        t0 = clock()
        sess.run_with_iobinding(io)
        lat[i] = clock() - t0
    return lat


def loop_latency(loop: StreamLoop, frames: np.ndarray) -> np.ndarray:
    """Per-decision ns of the full loop, frame arrival to decision."""
    loop.reset()
    # Timestamps at the bundle's frame rate: one per second would make every frame a
    # gap (the loop's slower time path) and time that instead.
    rate_hz = loop.bundle.manifest.frame.rate_hz
    return loop.run(
        ReplaySource(frames, np.arange(len(frames), dtype=np.float64) / rate_hz)
    ).latency_ns


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--keep",
        type=Path,
        help="write the three bundles (with replay.npz) into this folder and keep them, "
        "e.g. to try `slipkit-run <folder>/fsr_linear --check`",
    )
    args = parser.parse_args()
    print(
        f"onnxruntime {ort.__version__}, numpy {np.__version__}, {os.cpu_count()} CPUs; "
        f"{args.frames} frames x {args.repeats} rounds (median of per-round percentiles), "
        "1 intra-op thread; us per frame"
    )
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) if args.keep is None else args.keep
        cases = build_cases(root, args.frames)
        rows = []
        for bundle, frames in cases:
            xs = model_inputs(bundle, frames)
            loops = {
                "run": StreamLoop(bundle, io_binding=False),
                "bind": StreamLoop(bundle, io_binding=True),
            }
            fns = {
                "bare run": lambda b=bundle, x=xs: bare_run(b, x),
                "bare bind": lambda b=bundle, x=xs: bare_bind(b, x),
                "loop run": lambda f=frames, lp=loops["run"]: loop_latency(lp, f),
                "loop bind": lambda f=frames, lp=loops["bind"]: loop_latency(lp, f),
            }
            for fn in fns.values():
                fn()  # warm-up pass
            stats: dict[str, list[tuple[float, float]]] = {k: [] for k in fns}
            for _ in range(args.repeats):
                for key, fn in fns.items():
                    p50, p99 = np.percentile(fn() / 1e3, [50, 99])
                    stats[key].append((p50, p99))
            med = {k: np.median(np.asarray(v), axis=0) for k, v in stats.items()}
            rows.append((bundle.manifest, med))
    head = (
        "| graph | bare run p50 / p99 | bare bind p50 / p99 | loop run p50 / p99 | "
        "loop bind p50 / p99 | loop - bare p50 (bind) | loop / bare p50 (bind) | "
        "budget p99 | met |"
    )
    print()
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for m, med in rows:
        keys = ("bare run", "bare bind", "loop run", "loop bind")
        cells = [f"{med[k][0]:.1f} / {med[k][1]:.1f}" for k in keys]
        budget_us = m.budget.p99_ms * 1e3
        extra = med["loop bind"][0] - med["bare bind"][0]
        ratio = med["loop bind"][0] / med["bare bind"][0]
        met = "yes" if med["loop bind"][1] <= budget_us else "NO"
        print(
            f"| {m.name} | "
            + " | ".join(cells)
            + f" | {extra:.1f} | {ratio:.2f}x | {budget_us:.0f} | {met} |"
        )


if __name__ == "__main__":
    main()
