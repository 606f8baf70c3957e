"""SlipTack's classes stay importable, and unpicklable, by the module paths saved run folders
name them with (``model.joblib`` pickles, ``config.yaml`` ``_target_`` strings)."""

from __future__ import annotations

import importlib
import pickle
from pathlib import Path

import numpy as np
import pytest

from slipkit.families.sliptack.speed import StickSlipSpeed

#: (old module, name, module in the family folder)
OLD_PATHS = [
    ("slipkit.baselines.sliptack", "StickSlipSpeed", "slipkit.families.sliptack.speed"),
    (
        "slipkit.baselines.sliptack",
        "DropAcceleration",
        "slipkit.families.sliptack.accel",
    ),
    (
        "slipkit.baselines.sliptack",
        "TorsionalSlipDetector",
        "slipkit.families.sliptack.torsion",
    ),
    (
        "slipkit.baselines.sliptack_accel",
        "DropAcceleration",
        "slipkit.families.sliptack.accel",
    ),
    (
        "slipkit.baselines.sliptack_onset",
        "SlipTackOnset",
        "slipkit.families.sliptack.onset",
    ),
    (
        "slipkit.baselines.sliptack_onset",
        "SlipTackOnsetLogistic",
        "slipkit.families.sliptack.onset",
    ),
    (
        "slipkit.baselines.sliptack_torsion",
        "TorsionalSlipDetector",
        "slipkit.families.sliptack.torsion",
    ),
    (
        "slipkit.models.spectral",
        "SpectralSpeedRegressor",
        "slipkit.families.sliptack.spectral",
    ),
    (
        "slipkit.export.sliptack",
        "SpeedSlipDetector",
        "slipkit.families.sliptack.export.detector",
    ),
    (
        "slipkit.export.sliptack_detector",
        "SpeedSlipDetector",
        "slipkit.families.sliptack.export.detector",
    ),
    (
        "slipkit.export.spectral",
        "SpectralSlipDetector",
        "slipkit.families.sliptack.export.spectral",
    ),
    ("slipkit.train.tasks.sliptack", "SlipTackSpeed", "slipkit.families.sliptack.task"),
    ("slipkit.train.tasks.sliptack", "SlipTackAccel", "slipkit.families.sliptack.task"),
    ("slipkit.sim.scenes.sliptack", "SlipTackPull", "slipkit.families.sliptack.scene"),
    ("slipkit.sim.scenes.sliptack", "SlipTackDrop", "slipkit.families.sliptack.scene"),
]


@pytest.mark.parametrize(("old", "name", "new"), OLD_PATHS)
def test_old_path_gives_the_same_class(old: str, name: str, new: str) -> None:
    """getattr on the old module (what pickle and Hydra's _target_ do) returns the class
    defined in the family folder."""
    cls = getattr(importlib.import_module(new), name)
    assert (new, cls) == (cls.__module__, getattr(importlib.import_module(old), name))


def test_a_fitted_estimator_pickled_under_the_old_path_loads() -> None:
    """A StickSlipSpeed pickled when it lived in slipkit.baselines.sliptack unpickles to the
    family's class, fitted state included."""
    rng = np.random.default_rng(0)
    t = np.arange(2000) / 1000.0
    x = np.sin(2 * np.pi * 40 * t) + 0.05 * rng.normal(size=len(t))
    y = np.full(len(t), 40.0)
    est = StickSlipSpeed(rate_hz=1000.0, window=500, hop=100).fit(x[:, None], y)
    text = pickle.dumps(est, protocol=0)
    assert StickSlipSpeed.__module__ == "slipkit.families.sliptack.speed"
    old = text.replace(
        b"slipkit.families.sliptack.speed\n", b"slipkit.baselines.sliptack\n"
    )
    assert b"slipkit.families.sliptack.speed" not in old
    loaded = pickle.loads(old)
    assert StickSlipSpeed is type(loaded)
    np.testing.assert_array_equal(est.predict(x[:, None]), loaded.predict(x[:, None]))


def test_shims_are_one_import_and_name_estimators_tasks_or_scenes_only() -> None:
    """Each old-path module is its docstring and one import from the family folder."""
    src = Path(importlib.import_module("slipkit").__file__).parent  # type: ignore[arg-type]
    olds = sorted({old for old, _, _ in OLD_PATHS})
    for old in olds:
        path = src.joinpath(*old.split(".")[1:]).with_suffix(".py")
        code = [
            line
            for line in path.read_text().splitlines()[1:]
            if line.strip() and not line.startswith('"""')
        ]
        assert len(code) >= 1
        assert all(line.startswith("from slipkit.families.sliptack.") for line in code)
