"""Classes that moved to their own modules stay importable, and unpicklable, by their old
module path: saved run folders (``model.joblib``) and configs name them that way."""

from __future__ import annotations

import importlib
import pickle

import pytest

#: (old module, name, new module)
MOVED = [
    (
        "slipkit.baselines.sliptack",
        "DropAcceleration",
        "slipkit.baselines.sliptack_accel",
    ),
    (
        "slipkit.baselines.sliptack",
        "AccelerationStream",
        "slipkit.baselines.sliptack_accel",
    ),
    (
        "slipkit.baselines.sliptack",
        "TorsionalSlipDetector",
        "slipkit.baselines.sliptack_torsion",
    ),
    (
        "slipkit.export.sliptack",
        "SpeedSlipDetector",
        "slipkit.export.sliptack_detector",
    ),
    (
        "slipkit.export.sliptack",
        "export_speed_slip_detector",
        "slipkit.export.sliptack_detector",
    ),
    ("slipkit.export.sliptack", "main", "slipkit.export.sliptack_parity"),
    (
        "slipkit.train.tasks.force",
        "FingerDirection",
        "slipkit.train.tasks.force_direction",
    ),
]


@pytest.mark.parametrize(("old", "name", "new"), MOVED)
def test_old_path_gives_the_same_class(old: str, name: str, new: str) -> None:
    """getattr on the old module (what pickle and Hydra's _target_ do) returns the class."""
    cls = getattr(importlib.import_module(new), name)
    assert cls is getattr(importlib.import_module(old), name)


def test_a_pickle_naming_the_old_module_loads() -> None:
    """An estimator pickled when it lived in the old module unpickles to the moved class."""
    from slipkit.baselines.sliptack_accel import DropAcceleration

    text = pickle.dumps(DropAcceleration(), protocol=0)
    old = text.replace(
        b"slipkit.baselines.sliptack_accel\n", b"slipkit.baselines.sliptack\n"
    )
    assert b"slipkit.baselines.sliptack\n" in old
    assert DropAcceleration is type(pickle.loads(old))


def test_an_unknown_name_is_still_an_attribute_error() -> None:
    """The old module's lazy lookup does not invent names."""
    mod = importlib.import_module("slipkit.baselines.sliptack")
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        mod.Nope  # noqa: B018
