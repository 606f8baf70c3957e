"""TacTip SVM per-frame latency, side by side: sklearn, skl2onnx's SVMClassifier, slipkit's graph.

Run: ``.venv/bin/python benchmarks/bench_export_svm.py [--trials 20] [--gamma 0.0065]``.

One process, one thread (BLAS/OpenMP pinned before numpy loads, onnxruntime with
one intra-op thread), batch 1, the same held-out frames for every contender:

* ``sklearn predict`` / ``sklearn decision_function``: the fitted
  :class:`~slipkit.models.svm.TacTipSVM` (scaler + libsvm);
* ``skl2onnx SVMClassifier``: ``skl2onnx.to_onnx(svm.model_)`` in onnxruntime
  (the ``ai.onnx.ml`` SVM operator, all outputs);
* ``slipkit graph``: :func:`slipkit.families.tactip.export.svm.export_tactip_svm` (Gemm/Exp) in
  onnxruntime, and the same with the pin-velocity features inside (raw pin
  frames in);
* ``numpy matmul``: the same expansion as the graph, float32 numpy (and with
  :func:`~slipkit.features.pins.velocity_features` in front, from pin frames);
* ``onnxruntime Identity``: the per-call floor of ``session.run``.

The floor of issue 6 is the best of the numpy time and the Identity floor plus the
graph's FLOPs at this CPU's measured single-thread float32 matmul rate. Targets:
graph >= 4x faster than sklearn ``predict``, within 2x of the floor, and >= 30x
faster than the paper's 3 ms per frame (James et al. 2018).

The model: the Gaussian SVM on standardised (dr, dtheta) features of simulated
``tactip_gravity_drop`` trials (127 pins -> 254 features). The paper's KS/BC give
~100 support vectors on this clean simulated scene, so ``gamma`` is raised to
reach about the issue's reference size (1128 SVs); the SV count is printed.
"""

from __future__ import annotations

import os

# One core: pin BLAS/OpenMP pools before numpy loads.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import onnx  # noqa: E402
from hydra import compose, initialize_config_dir  # noqa: E402
from onnx import TensorProto, helper  # noqa: E402

from slipkit import config_dir  # noqa: E402
from slipkit.export import export_velocity_features  # noqa: E402
from slipkit.export.parity import check_parity, onnx_session  # noqa: E402
from slipkit.export.registry import ExportedGraph, finalize_model  # noqa: E402
from slipkit.families.tactip.export.svm import export_tactip_svm  # noqa: E402
from slipkit.families.tactip.features import dataset_features  # noqa: E402
from slipkit.features.pins import velocity_features  # noqa: E402
from slipkit.models import TacTipSVM  # noqa: E402
from slipkit.sim.commands import build_scene  # noqa: E402

PAPER_US = 3000.0  # the paper's SVM time per frame, us (James et al. 2018)


def simulate(n_trials: int, seed: int) -> Any:
    """``n_trials`` simulated gravity-drop trials."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=tactip_gravity_drop"])
    return build_scene(cfg.scene).simulate(n_trials, seed=seed)


def pin_pairs(dataset: Any) -> np.ndarray:
    """(n, 2, 2N) previous/current pin frames of every trial, float64 (mm)."""
    pairs = []
    for trial in dataset:
        f = trial.streams["pins"].drop(columns="t").to_numpy(dtype=np.float64)
        pairs.append(np.stack([f[:-1], f[1:]], axis=1))
    return np.concatenate(pairs)


def time_per_frame(
    fn: Callable[[np.ndarray], Any], frames: np.ndarray, repeats: int
) -> np.ndarray:
    """Wall time of ``fn(frame[None])`` per frame, us (after a warm-up pass)."""
    for x in frames[:50]:
        fn(x[None])
    out = []
    clock = time.perf_counter_ns
    for _ in range(repeats):
        for x in frames:
            xb = x[None]
            t0 = clock()
            fn(xb)
            out.append(clock() - t0)
    return np.asarray(out, dtype=np.float64) / 1e3


def identity_graph(n_features: int) -> onnx.ModelProto:
    """An Identity graph: onnxruntime's per-call floor."""
    g = helper.make_graph(
        [helper.make_node("Identity", ["x"], ["y"])],
        "identity",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["batch", n_features])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["batch", n_features])],
    )
    return finalize_model(
        helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])
    )


def numpy_svm(svm: TacTipSVM) -> Callable[[np.ndarray], np.ndarray]:
    """The graph's expansion as float32 numpy matrix products."""
    sv = svm.svc_.support_vectors_
    centre = sv.mean(axis=0)
    mean, scale = svm.scaler_.mean_, svm.scaler_.scale_
    root = np.sqrt(svm.gamma_)
    shift = (mean + centre * scale).astype(np.float32)
    mult = (root / scale).astype(np.float32)
    s = root * (sv - centre)
    s2t = np.ascontiguousarray((2.0 * s.T).astype(np.float32))
    sn = (-np.sum(s * s, axis=1)).astype(np.float32)
    dual = svm.svc_.dual_coef_.ravel().astype(np.float32)
    b = np.float32(svm.svc_.intercept_[0])

    def score(x: np.ndarray) -> np.ndarray:
        z = (x - shift) * mult
        k = np.exp(z @ s2t + sn - np.einsum("ij,ij->i", z, z)[:, None])
        return k @ dual + b

    return score


def matmul_gflops(n_features: int, n_sv: int, batch: int) -> float:
    """Single-thread float32 numpy matmul rate, GFLOP/s, for ``(batch, F) @ (F, n_sv)``."""
    rng = np.random.default_rng(0)
    a = rng.normal(size=(batch, n_features)).astype(np.float32)
    b = rng.normal(size=(n_features, n_sv)).astype(np.float32)
    best = float("inf")
    for _ in range(200):
        t0 = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - t0)
    return 2.0 * batch * n_features * n_sv / best / 1e9


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20, help="training trials")
    parser.add_argument("--gamma", type=float, default=0.0065)
    parser.add_argument("--frames", type=int, default=300, help="timed frames")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    train = dataset_features(simulate(args.trials, seed=0))
    held = simulate(2, seed=1)
    X = dataset_features(held).X[: args.frames]
    pins64 = pin_pairs(held)[: args.frames]
    pins = pins64.astype(np.float32)
    svm = TacTipSVM(standardize=True, gamma=args.gamma, class_weight="balanced").fit(
        train.X, train.y
    )
    n_sv, n_features = svm.svc_.support_vectors_.shape

    graph = export_tactip_svm(svm)
    graph_pins = export_tactip_svm(svm, with_features=True)
    from skl2onnx import to_onnx
    from skl2onnx.common.data_types import FloatTensorType

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        skl = to_onnx(
            svm.model_,
            initial_types=[("X", FloatTensorType([None, n_features]))],
            target_opset={"": 17, "ai.onnx.ml": 3},
        )
    skl.ir_version = 10

    def session(model: onnx.ModelProto) -> Any:
        return onnx_session(
            ExportedGraph(model, "x", ("batch",), ("y",), "y", "", "transform", 17)
        )

    s_graph, s_pins = onnx_session(graph), onnx_session(graph_pins)
    s_skl, s_id = session(skl), session(identity_graph(n_features))
    X32 = X.astype(np.float32)
    np_score = numpy_svm(svm)
    n_pins = n_features // 2

    def np_pins_score(p: np.ndarray) -> np.ndarray:
        d = p[:, 1].astype(np.float64) - p[:, 0]
        dxy = np.stack([d[:, :n_pins], d[:, n_pins:]], axis=-1)
        return np_score(velocity_features(dxy).astype(np.float32))

    contenders: list[tuple[str, Callable[[np.ndarray], Any], np.ndarray]] = [
        ("sklearn predict", svm.predict, X),
        ("sklearn decision_function", svm.decision_function, X),
        ("skl2onnx SVMClassifier (ort)", lambda x: s_skl.run(None, {"X": x}), X32),
        ("slipkit graph (ort)", lambda x: s_graph.run(None, {"features": x}), X32),
        (
            "slipkit graph + features (ort)",
            lambda x: s_pins.run(None, {"pins": x}),
            pins,
        ),
        ("numpy matmul (float32)", np_score, X32),
        ("numpy features + matmul", np_pins_score, pins),
        ("onnxruntime Identity", lambda x: s_id.run(None, {"x": x}), X32),
    ]
    times = {
        name: time_per_frame(fn, frames, args.repeats)
        for name, fn, frames in contenders
    }
    p50 = {k: float(np.median(v)) for k, v in times.items()}
    p99 = {k: float(np.percentile(v, 99)) for k, v in times.items()}

    # The loop runs batch 1: a matrix-vector product that streams all support
    # vectors from cache/memory each call, far below the batched GEMM rate. The
    # floor uses the rate measured at batch 1; the batch-64 rate is printed too.
    rate = matmul_gflops(n_features, n_sv, batch=1)
    rate64 = matmul_gflops(n_features, n_sv, batch=64)
    flops = 2 * n_features * n_sv + 2 * n_sv + 6 * n_sv + 4 * n_features
    ort_floor = p50["onnxruntime Identity"] + flops / (rate * 1e3)
    floor = min(p50["numpy matmul (float32)"], ort_floor)
    ours = p50["slipkit graph (ort)"]
    parity = check_parity(svm, graph, X)
    # Float32 absolute positions (the input contract) against float64 features.
    from slipkit.export.parity import run_graph

    feats = run_graph(export_velocity_features(n_features // 2), pins)
    blur = np.abs((feats - X + np.pi) % (2 * np.pi) - np.pi)[:, n_features // 2 :]
    ref = svm.decision_function(X)
    via_pins = run_graph(graph_pins, pins)

    print(
        f"TacTip RBF SVM: {n_sv} support vectors x {n_features} features "
        f"(gamma {args.gamma}, standardised), {len(X)} held-out frames x {args.repeats}, "
        "batch 1, 1 thread"
    )
    print(f"{'implementation':34s} {'p50 us':>9s} {'p99 us':>9s} {'vs graph':>9s}")
    for name in times:
        print(f"{name:34s} {p50[name]:9.1f} {p99[name]:9.1f} {p50[name] / ours:8.2f}x")
    print(
        f"float32 matmul rate at batch 1: {rate:.1f} GFLOP/s (batch 64: {rate64:.1f}); "
        f"graph {flops / 1e6:.2f} MFLOP/frame"
    )
    print(
        f"ort floor = Identity + FLOPs/rate = {ort_floor:.1f} us "
        f"(with the batch-64 rate: {p50['onnxruntime Identity'] + flops / (rate64 * 1e3):.1f} us); "
        f"best floor = min(numpy, ort floor) = {floor:.1f} us"
    )
    speedup = p50["sklearn predict"] / ours
    print(
        f"graph vs sklearn predict: {speedup:.1f}x faster (target >= 4x): "
        f"{'PASS' if speedup >= 4 else 'MISS'}"
    )
    print(
        f"graph vs best floor: {ours / floor:.2f}x (target <= 2x): "
        f"{'PASS' if ours <= 2 * floor else 'MISS'}; vs the batch-64-rate floor: "
        f"{ours / (p50['onnxruntime Identity'] + flops / (rate64 * 1e3)):.2f}x"
    )
    with_f = p50["slipkit graph + features (ort)"]
    np_f = p50["numpy features + matmul"]
    print(
        f"graph + features: {with_f:.1f} us vs numpy features + matmul {np_f:.1f} us: "
        f"{with_f / np_f:.2f}x (target <= 2x): {'PASS' if with_f <= 2 * np_f else 'MISS'}"
    )
    print(
        f"graph vs paper's {PAPER_US:.0f} us/frame: {PAPER_US / ours:.0f}x faster "
        f"(target >= 30x): {'PASS' if PAPER_US / ours >= 30 else 'MISS'}"
    )
    print(
        f"parity on these frames: agreement {parity['agreement']:.4f}, "
        f"max |score diff| {parity['max_abs_diff']:.2e} "
        f"({parity['max_rel_diff']:.1e} of max |score|), passed {parity['passed']}"
    )
    print(
        f"float32 pin positions vs float64 features: max dtheta diff {blur.max():.3f} rad, "
        f"max score diff {np.max(np.abs(via_pins - ref)) / np.max(np.abs(ref)):.1%} of max "
        f"|score|, decisions agree on {np.mean((via_pins > 0) == (ref > 0)):.2%} of frames"
    )


if __name__ == "__main__":
    main()
