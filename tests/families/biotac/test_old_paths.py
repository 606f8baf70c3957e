"""BioTac's classes stay importable, and unpicklable, by the module paths saved run folders
name them with (``model.joblib`` pickles, ``config.yaml`` ``_target_`` strings)."""

from __future__ import annotations

import importlib
import pickle
from pathlib import Path

import numpy as np
import pytest

from slipkit.families.biotac.detectors import ForceDerivative, PressureVibration
from slipkit.families.biotac.force import WeightedNormalsRegressor

_BT = "slipkit.families.biotac."

#: (old module, name, module in the family folder)
OLD_PATHS = [
    ("slipkit.baselines.biotac", "ForceDerivative", _BT + "detectors"),
    ("slipkit.baselines.biotac", "PressureVibration", _BT + "detectors"),
    ("slipkit.sim.scenes.biotac", "BioTacForceProbe", _BT + "scene"),
    ("slipkit.sim.scenes.biotac", "BioTacLiftSlip", _BT + "scene"),
    ("slipkit.models.force", "WeightedNormalsRegressor", _BT + "force"),
    ("slipkit.models.force", "LocalLinearRegressor", _BT + "force"),
    ("slipkit.models.force", "ForceMLP", _BT + "force"),
    ("slipkit.train.tasks.force", "ForceRegression", _BT + "force_task"),
    ("slipkit.train.tasks.force", "FingerDirection", _BT + "direction_task"),
    ("slipkit.train.tasks.force_direction", "FingerDirection", _BT + "direction_task"),
    ("slipkit.train.tasks.grasp", "GraspStability", _BT + "grasp_task"),
    ("slipkit.train.tasks.grasp", "GraspFeatures", _BT + "grasp_task"),
    ("slipkit.baselines.slip_type", "SlipTwistClassifier", _BT + "slip_twist"),
    (
        "slipkit.baselines.window_energy",
        "ElectrodeEnergyClassifier",
        _BT + "electrode_energy",
    ),
]


@pytest.mark.parametrize(("old", "name", "new"), OLD_PATHS)
def test_old_path_gives_the_same_object(old: str, name: str, new: str) -> None:
    """getattr on the old module (what pickle and Hydra's _target_ do) returns the object
    defined in the family folder."""
    obj = getattr(importlib.import_module(new), name)
    assert obj is getattr(importlib.import_module(old), name)
    if isinstance(obj, type):
        assert new == obj.__module__


def _signal(n_channels: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two seeded recordings: quiet, then a ramp with vibration from the middle (slip)."""
    rng = np.random.default_rng(0)
    xs, ys, segs = [], [], []
    for k in range(2):
        t = np.arange(600)
        slip = t >= 300
        x = rng.normal(0.0, 0.05, (600, n_channels)) + 5.0
        x[slip] += (np.sin(0.9 * t[slip]) * 3.0 - 0.01 * (t[slip] - 300))[:, None]
        xs.append(x)
        ys.append(slip.astype(int))
        segs.append(np.full(600, k))
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(segs)


@pytest.mark.parametrize(
    ("cls", "n_channels"), [(ForceDerivative, 2), (PressureVibration, 1)]
)
def test_a_fitted_detector_pickled_under_the_old_path_loads(
    cls: type, n_channels: int
) -> None:
    """A detector pickled when it lived in slipkit.baselines unpickles to the family's
    class, fitted state included (same scores)."""
    X, y, seg = _signal(n_channels)
    est = cls().fit(X, y, segments=seg)
    new, old = _BT + "detectors", "slipkit.baselines.biotac"
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


def test_a_fitted_force_model_pickled_under_the_old_path_loads() -> None:
    """A force regressor pickled when it lived in slipkit.models unpickles to the family's
    class, fitted state included (same predictions)."""
    rng = np.random.default_rng(0)
    X = rng.normal(1000.0, 50.0, (200, 19))
    y = X[:, :3] * 0.01 + rng.normal(0.0, 0.01, (200, 3))
    est = WeightedNormalsRegressor().fit(X, y)
    new, old = _BT + "force", "slipkit.models.force"
    text = pickle.dumps(est, protocol=0)
    moved = text.replace(f"{new}\n".encode(), f"{old}\n".encode())
    assert new.encode() not in moved
    loaded = pickle.loads(moved)
    assert WeightedNormalsRegressor is type(loaded)
    np.testing.assert_array_equal(est.predict(X), loaded.predict(X))


def test_shims_are_one_import_from_the_family_folder() -> None:
    """Each old-path module is its docstring and one import from the family folder (the
    force task's old module: two, it held the direction task too)."""
    src = Path(importlib.import_module("slipkit").__file__).parent  # type: ignore[arg-type]
    for old in sorted({old for old, _, _ in OLD_PATHS}):
        path = src.joinpath(*old.split(".")[1:]).with_suffix(".py")
        code = " ".join(
            line.strip()
            for line in path.read_text().splitlines()[1:]
            if line.strip() and not line.startswith('"""')
        )
        imports = code.split("from ")[1:]
        assert code.startswith("from ")
        assert len(imports) == (2 if old == "slipkit.train.tasks.force" else 1)
        assert all(i.startswith("slipkit.families.biotac.") for i in imports)
