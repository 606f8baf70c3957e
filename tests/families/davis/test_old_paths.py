"""DAVIS's classes stay importable, and unpicklable, by the module paths saved run folders
name them with (``model.joblib`` pickles, ``config.yaml`` ``_target_`` strings)."""

from __future__ import annotations

import importlib
import pickle
from pathlib import Path

import numpy as np
import pytest
from sklearn.base import BaseEstimator

from slipkit.families.davis.classifier import EventFrameClassifier
from slipkit.families.davis.onset import DavisOnset
from slipkit.families.davis.polarity import DavisPolarity

#: (old module, name, module in the family folder)
OLD_PATHS = [
    ("slipkit.baselines.davis", "DavisPolarity", "slipkit.families.davis.polarity"),
    ("slipkit.baselines.davis_onset", "DavisOnset", "slipkit.families.davis.onset"),
    (
        "slipkit.models.events",
        "EventFrameClassifier",
        "slipkit.families.davis.classifier",
    ),
    ("slipkit.sim.scenes.davis", "DavisRelease", "slipkit.families.davis.scene"),
    ("slipkit.train.tasks.davis", "DavisRelease", "slipkit.families.davis.task"),
]


def _events(seed: int) -> np.ndarray:
    """Two 0.2 s recordings of events ``t, x, y, polarity``: sparse noise, then from
    0.1 s a filled block of positive events every 5 ms (a loss of contact)."""
    rng = np.random.default_rng(seed)
    rows = []
    for t in np.arange(0.0, 0.2, 0.005):
        n = 5
        rows.append(
            np.column_stack(
                [
                    np.full(n, t),
                    rng.integers(0, 190, n),
                    rng.integers(0, 180, n),
                    rng.choice([-1, 1], n),
                ]
            )
        )
        if t >= 0.1:
            xs, ys = np.meshgrid(np.arange(40, 48), np.arange(60, 62))
            rows.append(
                np.column_stack(
                    [
                        np.full(xs.size, t + 1e-4),
                        xs.ravel(),
                        ys.ravel(),
                        np.ones(xs.size),
                    ]
                )
            )
    one = np.concatenate(rows).astype(np.float64)
    return np.concatenate([one, one])


@pytest.mark.parametrize(("old", "name", "new"), OLD_PATHS)
def test_old_path_gives_the_same_class(old: str, name: str, new: str) -> None:
    """getattr on the old module (what pickle and Hydra's _target_ do) returns the class
    defined in the family folder."""
    cls = getattr(importlib.import_module(new), name)
    assert (new, cls) == (cls.__module__, getattr(importlib.import_module(old), name))


@pytest.mark.parametrize(
    ("cls", "old"),
    [
        (DavisPolarity, "slipkit.baselines.davis"),
        (DavisOnset, "slipkit.baselines.davis_onset"),
        (EventFrameClassifier, "slipkit.models.events"),
    ],
)
def test_a_fitted_estimator_pickled_under_the_old_path_loads(
    cls: type[BaseEstimator], old: str
) -> None:
    """An estimator pickled when it lived at its old path unpickles to the family's
    class, fitted state included (same decisions)."""
    X = _events(0)
    segments = np.repeat([0, 1], len(X) // 2)
    if cls is EventFrameClassifier:
        est = cls().fit(X, segments=segments, onsets=[0.1, 0.1], ends=[np.inf, np.inf])
    else:
        est = cls().fit(X)
    text = pickle.dumps(est, protocol=0)
    new = cls.__module__
    assert new.startswith("slipkit.families.davis.")
    moved = text.replace(f"{new}\n".encode(), f"{old}\n".encode())
    assert new.encode() not in moved
    loaded = pickle.loads(moved)
    assert cls is type(loaded)
    decisions = est.frames(X, segments=segments)["slip"].to_numpy()
    assert 0 < decisions.sum() < len(decisions)  # decisions of both kinds compared
    np.testing.assert_array_equal(
        decisions, loaded.frames(X, segments=segments)["slip"].to_numpy()
    )


def test_shims_are_one_import_from_the_family_folder() -> None:
    """Each old-path module is its docstring and one import from the family folder."""
    src = Path(importlib.import_module("slipkit").__file__).parent  # type: ignore[arg-type]
    for old in sorted({old for old, _, _ in OLD_PATHS}):
        path = src.joinpath(*old.split(".")[1:]).with_suffix(".py")
        code = [
            line
            for line in path.read_text().splitlines()[1:]
            if line.strip() and not line.startswith('"""')
        ]
        assert 1 == len(code)
        assert code[0].startswith("from slipkit.families.davis.")
