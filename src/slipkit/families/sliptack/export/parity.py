"""Parity and per-call time of the SlipTack speed graph on simulated recordings:
``python -m slipkit.families.sliptack.export.parity`` prints them.
"""

from __future__ import annotations

import numpy as np

from slipkit.families.sliptack.export.detector import (
    SpeedSlipDetector,
    export_speed_slip_detector,
)
from slipkit.families.sliptack.export.speed import export_stick_slip_speed, graph_speeds


def main() -> None:
    """Print parity and per-call time of the speed graph on simulated recordings.

    ``python -m slipkit.families.sliptack.export.parity [key=value ...]``: the ``sliptack_frequency``
    detector config (each ``key=value`` overrides ``detector.key``)
    (physics stick length, friction 0.55 / 0.45), 12 ``sliptack_pull`` trials (seed 1);
    per ``dft_dtype``: speed parity at the runtime's call instants (relative |diff|
    where both are defined, calls where only one is) and decision agreement at 0 and
    30 mm/s; time = median and p99 of 2000 batch-1 onnxruntime calls (one thread).
    """
    import sys
    import time

    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.utils import instantiate

    from slipkit import config_dir
    from slipkit.export.detectors import (
        _simulate,
        check_detector_parity,
        detector_windows,
    )
    from slipkit.export.parity import onnx_session

    # extra arguments override the detector config, e.g. ``interpolate=false``
    extra = [f"detector.{arg}" for arg in sys.argv[1:]]
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="train", overrides=["experiment=sliptack_speed", *extra]
        )
    GlobalHydra.instance().clear()
    est = instantiate(cfg.detector).fit(np.zeros((1, 1)), np.full(1, np.nan))
    ds = _simulate("sliptack_pull", 12, 1)
    xs = [
        tr.streams["nib"]["deflection"].to_numpy(dtype=np.float64)[:, None] for tr in ds
    ]
    X = np.concatenate(xs)
    seg = np.concatenate([np.full(len(x), k) for k, x in enumerate(xs)])
    ref_all = est.predict(X, segments=seg)
    print(
        f"{'dft_dtype':12s} {'W':>5s} {'hop':>3s} {'calls':>6s} {'max rel':>9s} "
        f"{'NaN mism':>8s} {'agree@0':>8s} {'agree@30':>8s} {'us p50':>7s} {'us p99':>7s}"
    )
    for dtype, prepare in (("float32", False), ("float64", False), ("float32", True)):
        graph = export_stick_slip_speed(est, dft_dtype=dtype, prepare=prepare)
        sess = onnx_session(graph)
        prep = graph.prepare_session() if prepare else None
        refs, ours = [], []
        for k, x in enumerate(xs):
            windows, inst = detector_windows(graph, x)
            ours.append(graph_speeds(graph.run_windows(sess, windows, prep)))
            refs.append(ref_all[seg == k][inst])
        ref, mine = np.concatenate(refs), np.concatenate(ours)
        both = np.isfinite(ref) & np.isfinite(mine)
        rel = np.abs(ref[both] - mine[both]) / np.abs(ref[both])
        agree = []
        for thr in (0.0, 30.0):
            det = SpeedSlipDetector(speed=est, threshold=thr).fit()
            rep = check_detector_parity(
                det,
                export_speed_slip_detector(det, dft_dtype=dtype, prepare=prepare),
                X,
                segments=seg,
            )
            agree.append(100 * rep["agreement"])
        # the decision frame's call (with prepare: the main graph on its prepared
        # tensor; the prepare graph's own call is timed beside it)
        times, prep_times = [], []
        for j in range(2000):
            w1 = windows[j % len(windows)][None]
            feed = {graph.input_name: w1}
            if prep is not None:
                earlier = np.concatenate([w1[:, :1], w1[:, :-1]], axis=1)
                t0 = time.perf_counter_ns()
                feed[graph.prepare_tensor] = prep.run(
                    [graph.prepare_tensor], {graph.input_name: earlier}
                )[0]
                prep_times.append(time.perf_counter_ns() - t0)
            t0 = time.perf_counter_ns()
            sess.run([graph.score_output], feed)
            times.append(time.perf_counter_ns() - t0)
        name = dtype + (" prep" if prepare else "")
        print(
            f"{name:12s} {graph.window:5d} {graph.hop:3d} {len(ref):6d} "
            f"{float(rel.max()) if rel.size else 0.0:9.2e} "
            f"{int(np.sum(np.isfinite(ref) != np.isfinite(mine))):8d} {agree[0]:8.3f} "
            f"{agree[1]:8.3f} {np.median(times) / 1e3:7.1f} "
            f"{np.percentile(times, 99) / 1e3:7.1f}"
            + (
                f"  (prepare.onnx p50 {np.median(prep_times) / 1e3:.1f}, p99 "
                f"{np.percentile(prep_times, 99) / 1e3:.1f})"
                if prep_times
                else ""
            )
        )


if __name__ == "__main__":
    main()
