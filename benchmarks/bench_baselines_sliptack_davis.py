"""Compute per decision of the SlipTack and DAVIS baselines, batch vs streaming, on one core.

Run: ``.venv/bin/python benchmarks/bench_baselines_sliptack_davis.py [--trials N]``.
Each baseline runs on simulated trials of its scene (default configs) both ways: the
batch form over whole recordings and the streaming form fed one sample (SlipTack) or one
chunk of events per 10 ms frame (DAVIS) at a time. A *decision* is one output sample
(SlipTack: a speed / acceleration / flag per nib sample; a new frequency every ``hop``
samples) or one 10 ms frame (DAVIS). The budget column is the paper's frame period
(``/work/shared/PAPERS.md``, per-frame budgets): 1 ms at the ~1 kHz coupled mode, 10 ms per
DAVIS frame. Both forms must agree; the script says so per row.
"""

from __future__ import annotations

import os

# One core: pin BLAS/OpenMP pools before numpy loads.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from hydra import compose, initialize_config_dir  # noqa: E402
from hydra.core.global_hydra import GlobalHydra  # noqa: E402
from hydra.utils import instantiate  # noqa: E402

from slipkit import config_dir  # noqa: E402
from slipkit.data import Dataset  # noqa: E402
from slipkit.families.sliptack.torsion import TorsionalSlipDetector  # noqa: E402
from slipkit.sim.commands import build_scene  # noqa: E402


def simulate(scene: str, n: int) -> Dataset:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={scene}"])
    GlobalHydra.instance().clear()
    return build_scene(cfg.scene).simulate(n, seed=7, progress=False)


def detector(name: str) -> Any:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"detector={name}"])
    GlobalHydra.instance().clear()
    return instantiate(cfg.detector)


def best(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    out, t = None, float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        t = min(t, time.perf_counter() - start)
    return t, out


def nib(ds: Dataset) -> list[np.ndarray]:
    return [tr.streams["nib"][["deflection"]].to_numpy() for tr in ds]


def row(
    name: str, n: int, batch_s: float, stream_s: float, budget_ms: float, agree: bool
) -> None:
    b_us, s_us = 1e6 * batch_s / n, 1e6 * stream_s / n
    print(
        f"{name:<34}{n:>9}{b_us:>12.2f}{s_us:>12.2f}{budget_ms * 1e3:>11.0f}"
        f"{budget_ms * 1e3 / s_us:>10.0f}x  {'yes' if agree else 'NO'}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    print(
        f"{'baseline':<34}{'decisions':>9}{'batch us':>12}{'stream us':>12}"
        f"{'budget us':>11}{'headroom':>11}  agree"
    )

    pull = nib(simulate("sliptack_pull", args.trials))
    speed = detector("sliptack_frequency").fit(pull[0], np.full(len(pull[0]), np.nan))

    def speed_stream() -> list[np.ndarray]:
        outs = []
        for x in pull:
            st = speed.stream()
            outs.append(np.array([st.update(s)[1] for s in x]))
        return outs

    tb, vb = best(lambda: [speed.predict(x) for x in pull], args.repeats)
    ts, vs = best(speed_stream, args.repeats)
    n = sum(len(x) for x in pull)
    agree = all(
        np.array_equal(a, b, equal_nan=True) for a, b in zip(vb, vs, strict=True)
    )
    row("sliptack speed (f_d, eq. 3)", n, tb, ts, 1.0, agree)
    n_est = sum(max(0, (len(x) - speed.window) // speed.hop + 1) for x in pull)
    print(
        f"  one f_d estimate (window {speed.window}, every {speed.hop} samples): "
        f"{1e3 * tb / n_est:.2f} ms batch"
    )

    drop_ds = simulate("sliptack_drop", max(args.trials, 3))
    drop = nib(drop_ds)
    y = np.concatenate(
        [
            np.where(
                tr.streams["truth_motion"]["t"] >= tr.labels["release_s"] + 0.06,
                tr.streams["truth_motion"]["acceleration"],
                np.nan,
            )
            for tr in drop_ds
        ]
    )
    seg = np.concatenate([np.full(len(x), i) for i, x in enumerate(drop)])
    for feature in ("deflection", "frequency_slope"):
        est = detector("sliptack_accel").set_params(feature=feature)
        est.fit(np.concatenate(drop), y, segments=seg)

        def acc_stream(est: Any = est) -> list[np.ndarray]:
            outs = []
            for x in drop:
                st = est.stream()
                outs.append(np.array([st.update(s) for s in x]))
            return outs

        tb, ab = best(lambda est=est: [est.predict(x) for x in drop], args.repeats)
        ts, as_ = best(acc_stream, args.repeats)
        n = sum(len(x) for x in drop)
        agree = all(
            np.allclose(a, b, rtol=1e-10, atol=1e-12, equal_nan=True)
            for a, b in zip(ab, as_, strict=True)
        )
        row(f"sliptack accel ({feature})", n, tb, ts, 1.0, agree)

    tors = TorsionalSlipDetector(threshold=0.1).fit(pull[0], np.zeros(len(pull[0])))
    tb, db = best(lambda: [tors.predict(x) for x in pull], args.repeats)
    ts, ds_ = best(lambda: [tors.replay(x)[1].astype(int) for x in pull], args.repeats)
    n = sum(len(x) for x in pull)
    agree = all(np.array_equal(a, b) for a, b in zip(db, ds_, strict=True))
    row("sliptack torsional flag", n, tb, ts, 1.0, agree)

    davis_ds = simulate("davis_release", args.trials)
    events = [
        tr.streams["events"][["t", "x", "y", "polarity"]].to_numpy(np.float64)
        for tr in davis_ds
    ]
    det = detector("davis_polarity").fit(events[0])

    def davis_stream() -> list[list[bool]]:
        outs = []
        for ev in events:
            k = np.floor(ev[:, 0] / det.frame_s).astype(int)
            cuts = np.flatnonzero(np.diff(k)) + 1
            outs.append([r.slip for r in det.stream().feed(np.split(ev, cuts))])
        return outs

    tb, fb = best(
        lambda: [det.frames(ev)["slip"].tolist() for ev in events], args.repeats
    )
    ts, fs = best(davis_stream, args.repeats)
    n = sum(len(f) for f in fb)
    row("davis polarity (10 ms frame)", n, tb, ts, 10.0, fb == fs)
    print(
        f"events per frame: {sum(len(e) for e in events) / n:.0f} on average "
        f"({args.trials} trials)"
    )


if __name__ == "__main__":
    main()
