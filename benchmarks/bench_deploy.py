"""Exported models side by side: the slipkit loop, the bare onnxruntime call, the native model, the floor.

Trains one run per learned family and for the DAVIS onset rule (analytic, the whole
rule in the graph) (``slipkit.train.commands.train_main``), exports
each with ``slipkit export`` (``export_main``: parity checked, session options
measured), then measures in one process, batch 1, one thread, rounds interleaved:

* **loop**: :class:`slipkit.runtime.StreamLoop` on the bundle's replay frames, frame
  arrival to decision (ring buffer + preprocessing + onnxruntime + rule + debounce);
* **bare**: one ``run_with_iobinding`` call on precomputed graph inputs (the loop's
  own call path; for a step graph with a recurrent ``state``, the frame GRU, the state
  buffers are bound too and carried ``h_out -> h_in`` after each call, as the loop
  does: ``_bound_state``);
* **native**: the Python estimator's score method (sklearn / skorch / torch) on one
  frame's model input (for TacTip: the numpy pin-velocity features, then
  ``decision_function``; for the frame GRU: its numpy ``stream().update``, one GRU
  step with the state carried);
* **floor**: the best of onnxruntime's per-call floor (an Identity graph of the same
  input) + the graph's FLOPs at this CPU's measured single-thread numpy matmul rate
  (a step graph's by ``step_graph_flops``, which adds the GRU's head),
  and, for the TacTip SVM, hand-written numpy matrix products on the features.

Prints a markdown table (us per frame, medians over rounds of each round's
percentile) with the ratios, the paper's figures (TacTip SVM 3 ms per frame, James
et al. 2018; FSR 4.9 ms only when an FSR bundle exists) and the sensor budget.

    .venv/bin/python benchmarks/bench_deploy.py [--rounds 5] [--frames 2000] [--keep DIR]
        [--only NAME ...] [--before DIR] [--before-loop FILE]

``--before DIR`` (a folder of ``<family>/model.onnx``, e.g. an earlier run's ``--keep``
folder's ``exports``) adds a row per family with that earlier graph's bare call,
timed in the same rounds on the same inputs: a graph change before and after, side by
side in one run. ``--before-loop FILE`` (an earlier ``slipkit/runtime/loop.py``) runs
that version's ``StreamLoop`` on the earlier graph too, for the row's loop column
(preprocessing ops are this checkout's in both). The floor of a "before" row is the
current graph's; "budget" and "met" are left to the current row.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

#: name -> (train overrides, paper figure in us per frame or None, what it is)
RUNS: dict[str, tuple[list[str], float | None, str]] = {
    "tactip_svm": (
        ["experiment=tactip_svm"],
        3000.0,
        "TacTip SVM, 3 ms per frame (James et al. 2018)",
    ),
    "tactip_svm_1128": (
        [
            "experiment=tactip_svm",
            "dataset.n_trials=20",
            "model.gamma=0.009",
            "model.standardize=true",
        ],
        3000.0,
        "TacTip SVM, gamma raised to reach the issue's ~1128 support vectors",
    ),
    "fsr": (
        ["experiment=fsr_roc"],
        4900.0,
        "FSR touch-and-slip, 4.9 ms per decision (Gentile et al. 2020)",
    ),
    "sliptack": (
        ["experiment=sliptack_speed", "dataset.n_trials=6"],
        None,
        "SlipTack speed (analytic: DFT and peak search as a graph)",
    ),
    "force_mlp3": (
        [
            "experiment=biotac_force",
            "~task.compare",
            "dataset.n_trials=6",
            "scene.model.duration_s=20",
            "task.block_s=10",
        ],
        None,
        "",
    ),
    "force_normals": (
        [
            "experiment=biotac_force",
            "~task.compare",
            "model=force_normals",
            "dataset.n_trials=6",
            "scene.model.duration_s=20",
            "task.block_s=10",
        ],
        None,
        "",
    ),
    "force_lwr": (
        [
            "experiment=biotac_force",
            "~task.compare",
            "model=force_lwr",
            "dataset.n_trials=6",
            "scene.model.duration_s=20",
            "task.block_s=10",
        ],
        None,
        "",
    ),
    "window_mlp": (
        [
            "experiment=biotac_slip_type",
            "~task.compare",
            "dataset.n_trials=40",
            "task.sweep=[]",
            "task.first_frame_control=false",
            "task.dynamics=null",
            "model.max_epochs=20",
        ],
        None,
        "",
    ),
    "window_cnn": (
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
        None,
        "",
    ),
    # An analytic rule whose whole decision is the graph (event frames in, no
    # preprocessing op): the onset rule's Conv and moments on 2 x 180 x 190 frames.
    "davis_onset": (
        ["experiment=davis_release", "detector=davis_onset", "dataset.n_trials=4"],
        None,
        "DAVIS onset rule (5 ms event frames, the whole rule in the graph)",
    ),
    # A step graph with a recurrent state (frame + h_in -> score + h_out): the bare
    # call binds the state too (_bound_state), native is the detector's own per-frame
    # numpy stream (_state_scorers), the floor counts the head too (step_graph_flops).
    # Fewer trials and epochs than the experiment's 40 / 40: a quick run to time.
    "frame_gru": (
        ["experiment=biotac_slip_gru", "dataset.n_trials=12", "model.epochs=10"],
        None,
        "BioTac frame GRU (one step per 300 Hz frame, state carried)",
    ),
}


def _compose(name: str, overrides: list[str]) -> Any:
    from hydra import compose, initialize_config_dir

    from slipkit import config_dir

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=name, overrides=overrides)


def _pct(ns: list[int] | np.ndarray) -> tuple[float, float]:
    us = np.asarray(ns, dtype=np.float64) / 1e3
    p50, p99 = np.percentile(us, [50, 99])
    return float(p50), float(p99)


def _time_calls(fn: Any, items: Any) -> list[int]:
    clock = time.perf_counter_ns
    out = []
    for x in items:
        t0 = clock()
        fn(x)
        out.append(clock() - t0)
    return out


def matmul_rate() -> float:
    """Single-thread numpy matmul rate, FLOP/s (best of 5 on 256 x 256 x 256)."""
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(256, 256)), rng.normal(size=(256, 256))
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(10):
            a @ b
        best = min(best, (time.perf_counter() - t0) / 10)
    return 2 * 256**3 / best


def graph_flops(model_bytes: bytes, fallback: int | None) -> int:
    """2 K N per Gemm / MatMul with a constant (K, N) weight, batch 1 (others ignored)."""
    if fallback:
        return int(fallback)
    import onnx
    from onnx import numpy_helper

    m = onnx.load_from_string(model_bytes)
    shapes = {t.name: numpy_helper.to_array(t).shape for t in m.graph.initializer}
    flops = 0
    for node in m.graph.node:
        if node.op_type in ("Gemm", "MatMul") and len(node.input) > 1:
            shp = shapes.get(node.input[1])
            if shp is not None and len(shp) == 2:
                flops += 2 * int(shp[0]) * int(shp[1])
    return flops


def identity_floor(
    input_shape: list[int], frames: int, dtype: str = "float32"
) -> list[int]:
    """onnxruntime's per-call floor: an Identity graph on this input (shape and dtype),
    IOBinding, one thread."""
    import onnxruntime as ort
    from onnx import TensorProto, helper

    elem = TensorProto.DOUBLE if dtype == "float64" else TensorProto.FLOAT
    inp = helper.make_tensor_value_info("x", elem, input_shape)
    out = helper.make_tensor_value_info("y", elem, input_shape)
    g = helper.make_graph(
        [helper.make_node("Identity", ["x"], ["y"])], "id", [inp], [out]
    )
    model = helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 10
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    sess = ort.InferenceSession(
        model.SerializeToString(), opts, providers=["CPUExecutionProvider"]
    )
    x = np.zeros(input_shape, dtype)
    y = np.zeros(input_shape, dtype)
    b = sess.io_binding()
    b.bind_ortvalue_input("x", ort.OrtValue.ortvalue_from_numpy(x))
    b.bind_ortvalue_output("y", ort.OrtValue.ortvalue_from_numpy(y))
    for _ in range(50):
        sess.run_with_iobinding(b)
    return _time_calls(lambda _: sess.run_with_iobinding(b), range(frames))


def numpy_svm_floor(model: Any, feats: np.ndarray) -> list[int]:
    """The TacTip RBF SVM as numpy matrix products on one feature row (the issue's ~23 us)."""
    svc = model.svc_
    gamma = float(model.gamma_)
    sv = np.asarray(svc.support_vectors_)
    sv_sq = np.sum(sv * sv, axis=1)
    dual = np.asarray(svc.dual_coef_).ravel()
    b = float(np.asarray(svc.intercept_).ravel()[0])

    def one(x: np.ndarray) -> float:
        d = sv_sq - 2.0 * (sv @ x) + x @ x
        return float(dual @ np.exp(-gamma * d) + b)

    return _time_calls(one, feats)


def _bound(
    sess: Any,
    in_name: str,
    out_name: str,
    shape: list[int],
    extra: dict[str, np.ndarray] | None = None,
) -> Any:
    """A function ``x -> None`` that writes one input and runs the session through
    IOBinding (the input buffer in the graph's input dtype, float32 or float64).
    ``extra``: further inputs bound once (a prepared bundle's prepared tensor)."""
    import onnxruntime as ort

    dtype = np.float64 if sess.get_inputs()[0].type == "tensor(double)" else np.float32
    xb = np.zeros(shape, dtype)
    feeds = {in_name: xb, **(extra or {})}
    ob = np.zeros_like(np.asarray(sess.run([out_name], feeds)[0]))
    binding = sess.io_binding()
    for k, v in (extra or {}).items():
        binding.bind_ortvalue_input(k, ort.OrtValue.ortvalue_from_numpy(v))
    binding.bind_ortvalue_input(in_name, ort.OrtValue.ortvalue_from_numpy(xb))
    binding.bind_ortvalue_output(out_name, ort.OrtValue.ortvalue_from_numpy(ob))

    def call(x: np.ndarray) -> None:
        xb[0] = x
        sess.run_with_iobinding(binding)

    return call


def _bound_state(
    sess: Any, in_name: str, out_name: str, shape: list[int], state: Any
) -> Any:
    """The bare call of a step graph: :func:`_bound` with the recurrent state bound too.

    Each ``state`` entry (:class:`slipkit.runtime.bundle.StateSpec`) gets a
    preallocated input and output buffer bound once, as ``StreamLoop`` does; after
    every call the output is copied into the input, so the state is *carried*
    ``h_out -> h_in`` from one frame to the next (the loop's own per-frame work; a
    fixed state would leave the copy out). Starts from zeros and carries on across
    the frames it is given (the loop also zeroes it at a replay's trial gaps: once per
    trial, not per frame, so left out).

    Returns
    -------
    callable
        ``x -> out``: writes one input frame, runs the session through IOBinding,
        carries the state and returns the score output buffer (the same array every
        call, shape of the graph's score output).
    """
    import onnxruntime as ort

    dtype = np.float64 if sess.get_inputs()[0].type == "tensor(double)" else np.float32
    xb = np.zeros(shape, dtype)
    h_in = [np.zeros(s.shape, np.dtype(s.dtype)) for s in state]
    h_out = [np.zeros_like(h) for h in h_in]
    feed = {in_name: xb, **{s.input: h for s, h in zip(state, h_in, strict=True)}}
    ob = np.zeros_like(np.asarray(sess.run([out_name], feed)[0]))
    binding = sess.io_binding()
    keep = [  # referenced for the binding's lifetime: it reads and writes them in place
        ort.OrtValue.ortvalue_from_numpy(a) for a in (xb, ob, *h_in, *h_out)
    ]
    binding.bind_ortvalue_input(in_name, keep[0])
    binding.bind_ortvalue_output(out_name, keep[1])
    for i, s in enumerate(state):
        binding.bind_ortvalue_input(s.input, keep[2 + i])
        binding.bind_ortvalue_output(s.output, keep[2 + len(state) + i])
    pairs = tuple(zip(h_in, h_out, strict=True))

    def call(x: np.ndarray) -> np.ndarray:
        xb[0] = x
        sess.run_with_iobinding(binding)
        for h, h_next in pairs:
            np.copyto(h, h_next)
        return ob

    call.keep = keep  # type: ignore[attr-defined]
    return call


def _state_scorers(model: Any) -> tuple[Any, Any, Any]:
    """Native and torch-eager per-frame scorers of a recurrent (step-graph) detector.

    native: ``model.stream().update`` (for ``FrameGRUDetector``, ``GRUStream``: numpy
    float64, one GRU step on the standardised frame, state carried in the stream);
    the estimator's own per-frame path. torch: the module ``torch.onnx`` traced for the
    export (``slipkit.export.frame_gru._step_module``, standardisation folded), eager,
    state carried. Returns ``(native, eager, module)``.
    """
    import torch

    from slipkit.export.frame_gru import _step_module

    stream = model.stream()
    module = _step_module(model).eval()
    h = [torch.zeros(1, int(model.hidden), dtype=torch.float64)]

    def native(x: np.ndarray) -> None:
        stream.update(x)

    def eager(x: np.ndarray) -> None:
        with torch.no_grad():
            h[0] = module(torch.from_numpy(x[None]), h[0])[1]

    return native, eager, module


def step_graph_flops(model_bytes: bytes) -> int:
    """FLOPs of one call of a step graph, batch 1: :func:`graph_flops` plus what it leaves out.

    :func:`graph_flops` counts the Gemm / MatMul products with a constant 2-D weight,
    which in the frame GRU's graph are the input and recurrent projections
    (``2 x 3H x I`` and ``2 x 3H x H``). Added here: a MatMul with a constant 1-D weight
    (the GRU's linear head ``h . w_out``, 2 H) and, should a graph use onnxruntime's
    ``GRU`` op, each such node's ``2 x (W.size + R.size)`` per step, i.e.
    ``2 x 3 x H x (I + H)`` per direction (W: ``(D, 3H, I)``, R: ``(D, 3H, H)``; a step
    graph runs one step). Element-wise gate ops are ignored, as in every row.
    """
    import onnx
    from onnx import numpy_helper

    m = onnx.load_from_string(model_bytes)
    shapes = {t.name: numpy_helper.to_array(t).shape for t in m.graph.initializer}
    flops = graph_flops(model_bytes, None)
    for node in m.graph.node:
        if node.op_type == "MatMul":
            shp = shapes.get(node.input[1])
            if shp is not None and len(shp) == 1:
                flops += 2 * int(shp[0])
        elif node.op_type == "GRU":
            for w in node.input[1:3]:
                shp = shapes.get(w)
                if shp is not None:
                    flops += 2 * int(np.prod(shp))
    return flops


def profile_nodes(
    model_path: Path, options: Any, inputs: np.ndarray, top: int = 6
) -> list[str]:
    """The ``top`` slowest nodes by onnxruntime's profiler (median us over the calls).

    The profiler adds its own ~1-2 us per node, so the absolute values are high; the
    order says where a batch-1 call's time goes. Prints the total node count too.
    """
    import collections
    import json as _json

    import onnxruntime as ort

    with tempfile.TemporaryDirectory() as tmp:
        options.enable_profiling = True
        options.profile_file_prefix = str(Path(tmp) / "prof")
        sess = ort.InferenceSession(
            str(model_path), options, providers=["CPUExecutionProvider"]
        )
        name = sess.get_inputs()[0].name
        # a step graph's state inputs (zeros: the profile is of one call's nodes)
        zeros = {
            i.name: np.zeros(
                [d if isinstance(d, int) else 1 for d in i.shape], inputs.dtype
            )
            for i in sess.get_inputs()[1:]
        }
        for x in inputs:
            sess.run(None, {name: x[None], **zeros})
        events = _json.loads(Path(sess.end_profiling()).read_text())
    per: dict[tuple[str, str], list[int]] = collections.defaultdict(list)
    for e in events:
        if e.get("cat") == "Node" and e["name"].endswith("_kernel_time"):
            per[(e["args"]["op_name"], e["name"][: -len("_kernel_time")])].append(
                e["dur"]
            )
    ranked = sorted(((float(np.median(v)), k) for k, v in per.items()), reverse=True)
    total = sum(t for t, _ in ranked)
    return [f"{len(ranked)} nodes, profiled sum {total:.0f} us"] + [
        f"{op} {node}: {t:.0f} us" for t, (op, node) in ranked[:top]
    ]


def _median(
    stats: dict[str, list[tuple[float, float]]],
) -> dict[str, tuple[float, ...]]:
    return {k: tuple(np.median(np.asarray(v), axis=0)) for k, v in stats.items() if v}


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--frames", type=int, default=2000)
    ap.add_argument(
        "--keep", type=Path, default=None, help="keep runs and bundles here"
    )
    ap.add_argument("--only", nargs="*", default=None, help="families to run")
    ap.add_argument(
        "--before",
        type=Path,
        default=None,
        help="a folder of <family>/model.onnx (an earlier run's --keep DIR/exports): "
        "each family's earlier graph is timed too (bare call, same inputs and session "
        "options, in the same rounds) and printed as a 'before' row",
    )
    ap.add_argument(
        "--before-loop",
        type=Path,
        default=None,
        help="an earlier slipkit/runtime/loop.py (e.g. `git show <commit>:src/slipkit/"
        "runtime/loop.py > old_loop.py`): its StreamLoop runs each bundle too (on the "
        "--before graph when given), timed in the same rounds, as the 'before' row's loop",
    )
    ap.add_argument(
        "--profile-nodes",
        action="store_true",
        help="also print each bundle's slowest graph nodes (onnxruntime profiler, 300 "
        "calls; the profiler's own cost inflates every node)",
    )
    args = ap.parse_args()
    old_loop_cls = None
    if args.before_loop is not None:
        import importlib.util
        import sys

        spec = importlib.util.spec_from_file_location(
            "slipkit.runtime._before_loop", args.before_loop
        )
        assert spec is not None
        assert spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod
        spec.loader.exec_module(mod)
        old_loop_cls = mod.StreamLoop

    import onnxruntime as ort
    import torch

    torch.set_num_threads(1)
    from slipkit.export import export
    from slipkit.export.commands import export_main
    from slipkit.export.deploy import graph_inputs
    from slipkit.export.parity import estimator_inputs, estimator_score
    from slipkit.families.biotac.export import force as _force  # noqa: F401
    from slipkit.runtime import StreamLoop, load_bundle
    from slipkit.train.commands import train_main
    from slipkit.train.runs import read_run

    root = args.keep or Path(tempfile.mkdtemp(prefix="bench_deploy-"))
    rate = matmul_rate()
    names = [n for n in RUNS if args.only is None or n in args.only]
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    for name in names:
        overrides, paper, _ = RUNS[name]
        run_dir, bundle_dir = root / "runs" / name, root / "exports" / name
        if not (run_dir / "run.json").is_file():
            with contextlib.redirect_stdout(io.StringIO()):
                train_main(
                    _compose(
                        "train", [*overrides, f"run_dir={run_dir}", "overwrite=true"]
                    )
                )
        with contextlib.redirect_stdout(io.StringIO()):
            export_main(
                _compose(
                    "export", [f"run={run_dir}", f"out={bundle_dir}", "overwrite=true"]
                )
            )
        bundle = load_bundle(bundle_dir)
        m = bundle.manifest
        model = read_run(run_dir).model
        if isinstance(model, dict):  # SlipTack: per-material speed estimators
            from slipkit.families.sliptack.export.detector import SpeedSlipDetector

            model = SpeedSlipDetector(speed=model["*"], threshold=0.0).fit()
        # the graph's estimator: event frames in
        if type(model).__name__ == "DavisOnset":
            from slipkit.families.davis.export.onset import DavisOnsetScores

            model = DavisOnsetScores(detector=model).fit()
        svm = name.startswith("tactip_svm")
        graph = export(
            model,
            **({"with_features": True} if svm else {}),
            **({"prepare": True} if m.prepare is not None else {}),
        )
        replay = np.load(bundle_dir / "replay.npz")
        frames = replay["frames"][: args.frames]
        times = replay["timestamps"][: args.frames]
        in_shape = [int(s) for s in graph.input_shape[1:]]
        inputs, _ = graph_inputs(
            frames,
            m.raw["frame"],
            m.raw["preprocessing"],
            in_shape,
            skip_nonfinite=True,
        )
        (inp,) = m.inputs
        # the graph's own input dtype (float32, or float64 for the FSR and LWR graphs),
        # so the bare call's input write is a plain copy, as the loop's
        x32 = inputs.astype(inp.dtype)
        loop = StreamLoop(bundle)
        if m.state:  # a step graph: the state bound and carried too
            bare = _bound_state(
                bundle.session, inp.name, m.decision.output, [1, *in_shape], m.state
            )
        elif m.prepare is not None:
            # a prepared bundle (SlipTack): the decision frame's call, the prepared
            # tensor bound (its values from the first window: the main graph's cost
            # does not depend on them); the prepare graph's own call, the work of the
            # frame before, is timed beside it (a note under the table)
            assert bundle.prepare_session is not None
            part0 = bundle.prepare_session.run([m.prepare], {inp.name: x32[:1]})[0]
            bare = _bound(
                bundle.session,
                inp.name,
                m.decision.output,
                [1, *in_shape],
                {m.prepare: np.ascontiguousarray(part0)},
            )
            prep_bare = _bound(
                bundle.prepare_session, inp.name, m.prepare, [1, *in_shape]
            )
        else:
            bare = _bound(bundle.session, inp.name, m.decision.output, [1, *in_shape])
        detector = hasattr(graph, "first_decision")
        if detector:
            # native: the batch detector's decision_function on one window (its
            # last sample is the decision), the per-decision Python cost.
            def native(x: np.ndarray, est: Any = model, w: int = graph.window) -> None:
                est.decision_function(x.reshape(w, -1))  # (window, channels)

            feats = inputs[:1]
        else:

            def native(x: np.ndarray, est: Any = model, g: Any = graph) -> None:
                estimator_score(est, g, x[None])

            feats = np.asarray(estimator_inputs(graph, inputs[:500]), dtype=np.float64)
        stats: dict[str, list[tuple[float, float]]] = {
            k: [] for k in ("loop", "bare", "native", "torch", "identity", "numpy")
        }
        module = getattr(model, "module_", None)
        if module is not None:
            # torch eager on the module alone (inputs already standardised: a lower
            # bound for the estimator's own predict, which adds skorch and scalers).
            module.eval()

            def eager(x: np.ndarray, mod: Any = module) -> None:
                with torch.no_grad():
                    mod(torch.from_numpy(x[None]))

        if m.state:
            # a recurrent detector: one frame with its state carried (the window
            # decision_function above would restart from zeros every call)
            native, eager, module = _state_scorers(model)
        part: dict[str, list[tuple[float, float]]] = {
            k: [] for k in ("bare", "native", "identity", "prepare", "prepare_frames")
        }
        old_path = None if args.before is None else args.before / name / "model.onnx"
        old_bare = None
        if old_path is not None and old_path.is_file():
            old_sess = ort.InferenceSession(
                str(old_path),
                bundle.session_spec.options(),
                providers=["CPUExecutionProvider"],
            )
            # the earlier graph's own input dtype and shape (the FSR graph read a
            # float32 (batch, 10, 1) window before issue 16, float64 (batch, 10) now)
            old_in = old_sess.get_inputs()[0]
            old_shape = [1, *(int(d) for d in old_in.shape[1:])]
            old_bare = _bound(old_sess, inp.name, m.decision.output, old_shape)
            x_old = inputs.astype(
                np.float64 if old_in.type == "tensor(double)" else np.float32
            ).reshape(len(inputs), *old_shape[1:])
            part["before"] = []
        old_loop = None
        if old_loop_cls is not None:
            from dataclasses import replace

            old_bundle = (
                bundle if old_bare is None else replace(bundle, session=old_sess)
            )
            old_loop = old_loop_cls(old_bundle)
            part["before_loop"] = []
        if svm:
            # The SVM part alone (features in), as the reference figures.
            svm_graph = export(model)
            svm_sess = ort.InferenceSession(
                svm_graph.serialize(),
                bundle.session_spec.options(),
                providers=["CPUExecutionProvider"],
            )
            svm_bare = _bound(
                svm_sess,
                svm_graph.input_name,
                svm_graph.score_output,
                [1, feats.shape[1]],
            )
        for _ in range(args.rounds):
            loop.reset()
            for values, ts in zip(frames, times.tolist(), strict=True):
                loop.step(values, ts)
            stats["loop"].append(_pct(loop.result().latency_ns))
            stats["bare"].append(_pct(_time_calls(bare, x32)))
            if m.prepare is not None:
                part["prepare"].append(_pct(_time_calls(prep_bare, x32)))
                part["prepare_frames"].append(_pct(loop.result().prepare_latency_ns))
            if old_bare is not None:
                part["before"].append(_pct(_time_calls(old_bare, x_old)))
            if old_loop is not None:
                old_loop.reset()
                for values, ts in zip(frames, times.tolist(), strict=True):
                    old_loop.step(values, ts)
                part["before_loop"].append(_pct(old_loop.result().latency_ns))
            stats["native"].append(_pct(_time_calls(native, inputs[:300])))
            if module is not None:
                stats["torch"].append(_pct(_time_calls(eager, x32[:1000])))
            stats["identity"].append(
                _pct(identity_floor([1, *in_shape], 1000, str(inp.dtype)))
            )
            if svm:
                stats["numpy"].append(_pct(numpy_svm_floor(model, feats)))
                part["bare"].append(
                    _pct(_time_calls(svm_bare, feats.astype(np.float32)))
                )
                part["native"].append(
                    _pct(
                        _time_calls(
                            lambda x, est=model: est.predict(x[None]), feats[:300]
                        )
                    )
                )
                part["identity"].append(_pct(identity_floor([1, feats.shape[1]], 1000)))
        med = _median(stats)
        flops = graph_flops(
            graph.serialize(), getattr(model, "flops_per_window_", None)
        )
        if m.state:
            flops = step_graph_flops(graph.serialize())
        floor = med["identity"][0] + flops / rate * 1e6
        if "numpy" in med:
            floor = min(floor, med["numpy"][0])
        rows.append(
            {
                "model": f"{name} ({type(model).__name__})",
                "loop": med["loop"],
                "bare": med["bare"],
                "native": med["native"],
                "torch": med["torch"][0] if "torch" in med else None,
                "identity": med["identity"][0],
                "flops": flops,
                "numpy": med["numpy"][0] if "numpy" in med else None,
                "floor": floor,
                "paper": paper,
                "budget": m.budget.p99_ms * 1e3,
            }
        )
        n_nodes = len(graph.model.graph.node)
        if m.prepare is not None and part["prepare"]:
            pb = np.median(np.asarray(part["prepare"]), axis=0)
            pf = np.median(np.asarray(part["prepare_frames"]), axis=0)
            assert graph.prepare is not None
            notes.append(
                f"{name}: prepare.onnx ({len(graph.prepare.graph.node)} nodes, run on "
                f"the frame before each decision; the main graph {n_nodes} nodes): "
                f"bare p50 / p99 {pb[0]:.1f} / {pb[1]:.1f} us, the loop's prepare "
                f"frames (arrival -> done) {pf[0]:.1f} / {pf[1]:.1f} us"
            )
        if args.profile_nodes and m.prepare is None:
            lines = profile_nodes(
                bundle_dir / "model.onnx", bundle.session_spec.options(), x32[:300]
            )
            notes.append(f"{name} profile: " + "; ".join(lines))
        if old_bare is not None or old_loop is not None:
            import onnx

            pm_before = _median(part)
            if old_bare is not None:
                assert old_path is not None
                old_nodes = len(onnx.load(str(old_path)).graph.node)
                notes.append(f"{name}: {n_nodes} graph nodes (before: {old_nodes})")
                what = f"{old_nodes}-node graph of --before"
                old_flops = graph_flops(old_path.read_bytes(), None)
            else:
                notes.append(f"{name}: {n_nodes} graph nodes")
                what, old_flops = "this graph", flops
            if old_loop is not None:
                what += ", loop of --before-loop"
            rows.append(
                {
                    "model": f"{name}: before ({what})",
                    "loop": pm_before.get("before_loop"),
                    "bare": pm_before.get("before", med["bare"]),
                    "native": med["native"],
                    "torch": None,
                    "identity": med["identity"][0],
                    "flops": old_flops,
                    "numpy": None,
                    "floor": floor,
                    "paper": None,
                    "budget": None,
                }
            )
        else:
            notes.append(f"{name}: {n_nodes} graph nodes")
        if svm:
            n_sv = int(model.svc_.support_vectors_.shape[0])
            notes.append(f"{name}: {n_sv} support vectors on {feats.shape[1]} features")
            pm = _median(part)
            sflops = graph_flops(svm_graph.serialize(), None)
            rows.append(
                {
                    "model": f"{name}: SVM part only (features in; native = sklearn predict)",
                    "loop": None,
                    "bare": pm["bare"],
                    "native": pm["native"],
                    "torch": None,
                    "identity": pm["identity"][0],
                    "flops": sflops,
                    "numpy": med["numpy"][0],
                    "floor": min(
                        pm["identity"][0] + sflops / rate * 1e6, med["numpy"][0]
                    ),
                    "paper": None,
                    "budget": None,
                }
            )
    print(
        f"onnxruntime {ort.__version__}, numpy {np.__version__}, torch {torch.__version__}, "
        f"{os.cpu_count()} CPUs ({platform.processor() or platform.machine()}), load average "
        f"{os.getloadavg()[0]:.1f}; numpy matmul {rate / 1e9:.1f} GFLOP/s (1 thread); "
        f"{args.frames} replay frames x {args.rounds} rounds (median of per-round "
        "percentiles), batch 1, 1 intra-op thread; us per frame\n"
    )
    print(
        "| model | loop p50 / p99 | bare ORT p50 / p99 | native p50 | torch eager p50 | floor (ORT id + FLOPs; numpy) "
        "| bare / floor | loop / bare | native / bare | paper | paper / loop p50 | budget p99 | met |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        paper, loop_r = r["paper"], r["loop"]
        numpy_txt = "" if r["numpy"] is None else f"; numpy {r['numpy']:.1f}"
        cells = [
            r["model"],
            "-" if loop_r is None else f"{loop_r[0]:.1f} / {loop_r[1]:.1f}",
            f"{r['bare'][0]:.1f} / {r['bare'][1]:.1f}",
            f"{r['native'][0]:.1f}",
            "-" if r["torch"] is None else f"{r['torch']:.1f}",
            f"{r['floor']:.1f} ({r['identity']:.1f} + {r['flops']} FLOP{numpy_txt})",
            f"{r['bare'][0] / r['floor']:.2f}x",
            "-" if loop_r is None else f"{loop_r[0] / r['bare'][0]:.2f}x",
            f"{r['native'][0] / r['bare'][0]:.1f}x",
            "-" if paper is None else f"{paper:.0f}",
            "-" if paper is None or loop_r is None else f"{paper / loop_r[0]:.0f}x",
            "-" if r["budget"] is None else f"{r['budget']:.0f}",
            "-"
            if loop_r is None or r["budget"] is None
            else "yes"
            if loop_r[1] <= r["budget"]
            else "NO",
        ]
        print("| " + " | ".join(cells) + " |")
    print()
    for note in notes:
        print(note)
    if args.keep:
        print(json.dumps({"runs": str(root)}))


if __name__ == "__main__":
    main()
