"""Simulator throughput per scene on one core: scalar samples and frames per second.

Run: ``make bench`` or ``.venv/bin/python benchmarks/bench_simulate.py [--trials N]``.
Samples count every channel value of every stream row, once with the ground-truth
streams (``truth_*``, which the simulator computes too) and once for the sensor streams
alone; frames count stream rows. The FSR and SlipTack scenes must generate >= 1e6 sensor
samples/s on one core (issue 3). The pass mark counts all generated samples; the sensor-only
rate is printed beside it because short trials (``sliptack_drop``: 0.6 s at 1 kHz) spend
most of their time in the fixed per-trial cost of building tables (~0.5 ms a trial).

Every config in ``configs/scene/`` runs, the variants too (``<scene>_hard`` with per-trial
draws of effect parameters, ``tactip_gravity_drop_hard_331``, ``sliptack_pull_hard_30hz``,
``fsr_probe_slide_rising``). The hard FSR and SlipTack variants at their base rates must
meet the same target; ``sliptack_pull_hard_30hz`` is exempt: at 30 Hz a trial holds 66
samples, so its rate measures the per-trial overhead, not generation.
"""

from __future__ import annotations

import os

# One core: pin BLAS/OpenMP pools before numpy loads.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

from hydra import compose, initialize_config_dir  # noqa: E402

from slipkit import config_dir  # noqa: E402
from slipkit.sim.commands import build_scene  # noqa: E402

TARGET = 1e6  # samples per second, FSR and SlipTack scenes
MUST_MEET = (
    "fsr_probe_slide",
    "fsr_probe_slide_hard",
    "fsr_probe_slide_rising",
    "sliptack_pull",
    "sliptack_pull_hard",
    "sliptack_drop",
    "sliptack_drop_hard",
)


def measure(scene_name: str, n_trials: int, repeats: int) -> dict[str, float]:
    """Best-of-``repeats`` wall time to simulate ``n_trials`` trials (dataset assembly included)."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"scene={scene_name}"])
    scene = build_scene(cfg.scene)
    scene.simulate(1, seed=123)  # warm-up: imports, caches
    best = float("inf")
    ds = None
    for r in range(repeats):
        start = time.perf_counter()
        ds = scene.simulate(n_trials, seed=r)
        best = min(best, time.perf_counter() - start)
    assert ds is not None
    samples = sum(t.shape[0] * (t.shape[1] - 2) for t in ds.tables.values())
    sensor = sum(
        t.shape[0] * (t.shape[1] - 2)
        for n, t in ds.tables.items()
        if not n.startswith("truth")
    )
    frames = sum(len(t) for t in ds.tables.values())
    return {"seconds": best, "samples": samples, "sensor": sensor, "frames": frames}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--only", default="", help="run only scenes whose name contains this text"
    )
    args = parser.parse_args()
    scenes = sorted(
        p.stem for p in (config_dir() / "scene").glob("*.yaml") if args.only in p.stem
    )
    print(
        f"{'scene':<30}{'trials':>7}{'samples':>11}{'frames':>10}{'s':>8}{'Msamples/s':>11}"
        f"{'sensor Ms/s':>12}{'kframes/s':>10}{'all vs 1e6/s':>16}"
    )
    failed = []
    for name in scenes:
        m = measure(name, args.trials, args.repeats)
        rate = m["samples"] / m["seconds"]
        sensor_rate = m["sensor"] / m["seconds"]
        ratio = rate / TARGET
        flag = ""
        if name in MUST_MEET:
            flag = " ok" if ratio >= 1 else " MISSED"
            if ratio < 1:
                failed.append(name)
        print(
            f"{name:<30}{args.trials:>7}{m['samples']:>11.0f}{m['frames']:>10.0f}{m['seconds']:>8.3f}"
            f"{rate / 1e6:>11.2f}{sensor_rate / 1e6:>12.2f}{m['frames'] / m['seconds'] / 1e3:>10.1f}"
            f"{ratio:>15.1f}x{flag}"
        )
    if failed:
        raise SystemExit(f"below {TARGET:.0e} samples/s on one core: {failed}")


if __name__ == "__main__":
    main()
