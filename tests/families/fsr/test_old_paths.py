"""FSR's classes stay importable, and unpicklable, by the module paths saved run folders
name them with (``model.joblib`` pickles, ``config.yaml`` ``_target_`` strings)."""

from __future__ import annotations

import importlib
import pickle
from pathlib import Path

import numpy as np
import pytest
from tests.baselines.test_conventions import fsr_trials, stack

from slipkit.families.fsr.onset import FSROnset
from slipkit.families.fsr.touch_slip import FSRTouchSlip

#: (old module, name, module in the family folder)
OLD_PATHS = [
    ("slipkit.baselines.fsr", "FSRTouchSlip", "slipkit.families.fsr.touch_slip"),
    ("slipkit.baselines.fsr", "PolarityWarning", "slipkit.families.fsr.touch_slip"),
    ("slipkit.baselines.fsr_onset", "FSROnset", "slipkit.families.fsr.onset"),
    ("slipkit.baselines.fsr_onset", "FSROnsetLogistic", "slipkit.families.fsr.onset"),
    ("slipkit.sim.scenes.fsr", "FSRProbeSlide", "slipkit.families.fsr.scene"),
]


@pytest.mark.parametrize(("old", "name", "new"), OLD_PATHS)
def test_old_path_gives_the_same_class(old: str, name: str, new: str) -> None:
    """getattr on the old module (what pickle and Hydra's _target_ do) returns the class
    defined in the family folder."""
    cls = getattr(importlib.import_module(new), name)
    assert (new, cls) == (cls.__module__, getattr(importlib.import_module(old), name))


@pytest.mark.parametrize(
    ("cls", "new", "old"),
    [
        (FSRTouchSlip, "slipkit.families.fsr.touch_slip", "slipkit.baselines.fsr"),
        (FSROnset, "slipkit.families.fsr.onset", "slipkit.baselines.fsr_onset"),
    ],
)
def test_a_fitted_detector_pickled_under_the_old_path_loads(
    cls: type, new: str, old: str
) -> None:
    """A detector pickled when it lived in slipkit.baselines unpickles to the family's
    class, fitted state included (same scores)."""
    X, y, seg = stack(fsr_trials(40, 2, polarity="falling", slide=True))
    est = cls().fit(X, y, segments=seg)
    text = pickle.dumps(est, protocol=0)
    assert new == cls.__module__
    moved = text.replace(f"{new}\n".encode(), f"{old}\n".encode())
    assert new.encode() not in moved
    loaded = pickle.loads(moved)
    assert cls is type(loaded)
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
        assert code[0].startswith("from slipkit.families.fsr.")
