"""Analytic detectors: compute per decision, batch (vectorised) beside streaming (per update).

Run: ``.venv/bin/python benchmarks/bench_baselines.py [--trials N] [--repeats R]``.
Each detector scores simulated recordings of its paper's scene twice in one run: batch
(``decision_function`` over whole recordings with ``segments``) and streaming (one
``stream().update(sample)`` call per sample, the runtime loop's form). Times are
best-of-``repeats`` on one core. A *decision* is what the paper decides at once: one
5-sample block for the FSR detector (so streaming pays 5 updates per decision), one
sample for the BioTac ones. The paper's published time (FSR: 4.9 ms per decision, C on
an i5-4570) is printed beside, with the ratio paper / streaming.

Adding a detector is one :class:`Case` appended to :data:`CASES` (or passed to
:func:`main` from another benchmark file: ``main(extra=[Case(...)])``).
"""

from __future__ import annotations

import os

# One core: pin BLAS/OpenMP pools before numpy loads.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from hydra import compose, initialize_config_dir  # noqa: E402
from hydra.utils import instantiate  # noqa: E402

from slipkit import config_dir  # noqa: E402
from slipkit.data import Dataset  # noqa: E402
from slipkit.sim.commands import build_scene  # noqa: E402


@dataclass(frozen=True)
class Case:
    """One detector to time.

    Attributes
    ----------
    name : str
        Row label.
    detector : str
        ``configs/detector/<name>.yaml`` to instantiate.
    scene, stream : str
        The simulated scene and the stream fed to the detector.
    channels : sequence of str
        The stream's channels, in the detector's order.
    samples_per_decision : int
        Samples the paper decides on at once (FSR: a 5-sample block).
    paper_ms : float or None
        The paper's published time per decision (ms), if any.
    paper_note : str
        Where that time was measured.
    overrides : mapping
        Detector parameters set after instantiation (e.g. a fixed threshold).
    """

    name: str
    detector: str
    scene: str
    stream: str
    channels: Sequence[str]
    samples_per_decision: int = 1
    paper_ms: float | None = None
    paper_note: str = ""
    overrides: tuple[tuple[str, Any], ...] = ()


CASES: list[Case] = [
    Case(
        "fsr",
        "fsr",
        "fsr_probe_slide",
        "fsr",
        ("voltage",),
        samples_per_decision=5,
        paper_ms=4.9,
        paper_note="C, i5-4570",
        overrides=(("threshold", 8.0),),
    ),
    Case(
        "pressure_vibration", "pressure_vibration", "biotac_lift_slip", "pac", ("pac",)
    ),
    Case(
        "force_derivative",
        "force_derivative",
        "biotac_lift_slip",
        "truth_force",
        ("fx", "fy"),
    ),
]


def _compose(config_name: str, overrides: list[str]) -> Any:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(config_name=config_name, overrides=overrides)


def _data(scene: str, stream: str, channels: Sequence[str], n: int) -> tuple[Any, ...]:
    cfg = _compose("simulate", [f"scene={scene}"])
    ds: Dataset = build_scene(cfg.scene).simulate(n, seed=0)
    xs = [t.streams[stream][list(channels)].to_numpy(np.float64) for t in ds]
    seg = np.concatenate([np.full(len(x), k) for k, x in enumerate(xs)])
    return np.concatenate(xs), seg, xs


def _best(fn: Callable[[], object], repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def measure(case: Case, n_trials: int, repeats: int) -> dict[str, float]:
    """Seconds per sample, batch and streaming, for ``case`` on ``n_trials`` trials."""
    det = instantiate(_compose("train", [f"detector={case.detector}"]).detector)
    det.set_params(**dict(case.overrides))
    X, seg, xs = _data(case.scene, case.stream, case.channels, n_trials)
    det.fit(
        X, np.zeros(len(X), int) if det.threshold is not None else seg % 2, segments=seg
    )
    det.decision_function(X[:100])  # warm-up

    def streaming() -> None:
        for x in xs:
            state = det.stream()
            update = state.update
            for row in x:
                update(row)

    batch_s = _best(lambda: det.decision_function(X, segments=seg), repeats)
    stream_s = _best(streaming, max(1, repeats // 2))
    return {"samples": len(X), "batch": batch_s / len(X), "stream": stream_s / len(X)}


def main(extra: Sequence[Case] = ()) -> None:
    """Time every case of :data:`CASES` (plus ``extra``) and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(
        f"{'detector':<20}{'samples':>9}{'batch us/sample':>16}{'stream us/update':>17}"
        f"{'stream/batch':>13}{'per decision: batch ms':>23}{'stream ms':>10}"
        f"{'paper ms':>9}{'paper/stream':>13}"
    )
    for case in [*CASES, *extra]:
        m = measure(case, args.trials, args.repeats)
        k = case.samples_per_decision
        b_ms, s_ms = m["batch"] * k * 1e3, m["stream"] * k * 1e3
        paper = f"{case.paper_ms:>9.3g}" if case.paper_ms is not None else f"{'-':>9}"
        ratio = (
            f"{case.paper_ms / s_ms:>12.0f}x"
            if case.paper_ms is not None
            else f"{'-':>13}"
        )
        print(
            f"{case.name:<20}{m['samples']:>9.0f}{m['batch'] * 1e6:>16.3f}"
            f"{m['stream'] * 1e6:>17.2f}{m['stream'] / m['batch']:>12.0f}x"
            f"{b_ms:>23.5f}{s_ms:>10.4f}{paper}{ratio}"
            + (f"  ({case.paper_note})" if case.paper_note else "")
        )


if __name__ == "__main__":
    main()
