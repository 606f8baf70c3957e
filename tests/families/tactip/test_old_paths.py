"""TacTip's classes stay importable, and unpicklable, by the module paths saved run
folders name them with (``model.joblib`` pickles, ``config.yaml`` ``_target_`` strings)."""

from __future__ import annotations

import importlib
import pickle
from pathlib import Path

import numpy as np
import pytest
from tests.families.tactip.test_detector import stretch_then_snap

from slipkit.families.tactip.detector import PinMotionDetector

#: (old module, name, module in the family folder)
OLD_PATHS = [
    (
        "slipkit.baselines.tactip",
        "PinMotionDetector",
        "slipkit.families.tactip.detector",
    ),
    ("slipkit.sim.scenes.tactip", "TacTipGravityDrop", "slipkit.families.tactip.scene"),
    ("slipkit.train.tasks.tactip", "TacTipFrames", "slipkit.families.tactip.task"),
    (
        "slipkit.train.tasks.tactip_table",
        "TacTipTable1",
        "slipkit.families.tactip.task_table",
    ),
]


@pytest.mark.parametrize(("old", "name", "new"), OLD_PATHS)
def test_old_path_gives_the_same_class(old: str, name: str, new: str) -> None:
    """getattr on the old module (what pickle and Hydra's _target_ do) returns the class
    defined in the family folder."""
    cls = getattr(importlib.import_module(new), name)
    assert (new, cls) == (cls.__module__, getattr(importlib.import_module(old), name))


def test_a_fitted_detector_pickled_under_the_old_path_loads() -> None:
    """A pin-motion detector pickled when it lived in slipkit.baselines unpickles to the
    family's class, fitted state included (same scores)."""
    new, old = "slipkit.families.tactip.detector", "slipkit.baselines.tactip"
    parts = [stretch_then_snap(37, seed=seed) for seed in (0, 1)]
    X = np.vstack([x for x, _ in parts])
    y = np.concatenate([lab for _, lab in parts])
    seg = np.repeat([0, 1], [len(lab) for _, lab in parts])
    est = PinMotionDetector().fit(X, y, segments=seg)
    text = pickle.dumps(est, protocol=0)
    assert new == PinMotionDetector.__module__
    moved = text.replace(f"{new}\n".encode(), f"{old}\n".encode())
    assert new.encode() not in moved
    loaded = pickle.loads(moved)
    assert PinMotionDetector is type(loaded)
    np.testing.assert_array_equal(
        est.decision_function(X, segments=seg),
        loaded.decision_function(X, segments=seg),
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
        assert code[0].startswith("from slipkit.families.tactip.")
