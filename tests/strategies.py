"""Builders of small datasets shared by the tests (plain functions and Hypothesis strategies)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import strategies as st

from slipkit.data import Dataset, LabelSpec, StreamSpec, Trial

FORCE = StreamSpec(
    "force",
    ("fx", "fy", "fz"),
    {"fx": "N", "fy": "N", "fz": "N"},
    rate_hz=300.0,
    description="force plate",
)
EVENTS = StreamSpec(
    "events",
    ("x", "y", "polarity"),
    {"x": "px", "y": "px", "polarity": "1"},
    kind="events",
)
LABELS = {
    "slip_onset_s": LabelSpec("slip_onset_s", unit="s"),
    "slip_class": LabelSpec("slip_class", classes=("linear", "rotational")),
}


def make_dataset(
    n_trials: int = 6,
    n_frames: int = 300,
    n_objects: int = 3,
    seed: int = 0,
    with_events: bool = True,
) -> Dataset:
    """A small two-stream dataset: force at 300 Hz and an event stream."""
    rng = np.random.default_rng(seed)
    trials = []
    for i in range(n_trials):
        t = np.arange(n_frames) / 300.0
        force = pd.DataFrame(
            {
                "t": t,
                "fx": rng.normal(size=n_frames),
                "fy": rng.normal(size=n_frames),
                "fz": 1.0 + t,
            }
        )
        streams = {"force": force}
        if with_events:
            n_ev = int(rng.integers(0, 50))
            streams["events"] = pd.DataFrame(
                {
                    "t": np.sort(rng.uniform(0, t[-1], n_ev)),
                    "x": rng.integers(0, 190, n_ev),
                    "y": rng.integers(0, 180, n_ev),
                    "polarity": rng.choice([-1, 1], n_ev).astype(np.int8),
                }
            )
        onset = float(rng.uniform(0.2, 0.8)) if i % 3 else float("nan")
        trials.append(
            Trial(
                f"trial-{i:03d}",
                streams,
                labels={
                    "slip_onset_s": onset,
                    "slip_class": ["linear", "rotational"][i % 2],
                },
                meta={"object": f"obj{i % n_objects}"},
            )
        )
    streams_spec = {"force": FORCE, **({"events": EVENTS} if with_events else {})}
    return Dataset.from_trials(
        trials,
        sensor="biotac",
        streams=streams_spec,
        labels=LABELS,
        groups=("object",),
        provenance={"scene": "unit-test", "seed": seed},
        name="tiny",
    )


@st.composite
def trial_layouts(draw: st.DrawFn) -> tuple[list[int], list[str], float]:
    """Per-trial frame counts, object names and a block length (s) for split properties."""
    n = draw(st.integers(2, 12))
    frames = draw(st.lists(st.integers(1, 400), min_size=n, max_size=n))
    objects = draw(
        st.lists(st.sampled_from(["a", "b", "c", "d"]), min_size=n, max_size=n)
    )
    block_s = draw(st.floats(0.05, 2.0))
    return frames, objects, block_s


def dataset_from_layout(frames: list[int], objects: list[str]) -> Dataset:
    """A force-only dataset with the given frame counts and objects."""
    trials = [
        Trial(
            f"t{i}",
            {
                "force": pd.DataFrame(
                    {"t": np.arange(n) / 300.0, "fx": 0.0, "fy": 0.0, "fz": float(i)}
                )
            },
            labels={"slip_onset_s": float("nan"), "slip_class": "linear"},
            meta={"object": obj},
        )
        for i, (n, obj) in enumerate(zip(frames, objects, strict=True))
    ]
    return Dataset.from_trials(
        trials,
        sensor="biotac",
        streams={"force": FORCE},
        labels=LABELS,
        groups=("object",),
    )
