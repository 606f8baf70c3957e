"""Classes that moved to their own modules stay importable, and unpicklable, by their old
module path: saved run folders (``model.joblib``) and configs name them that way."""

from __future__ import annotations

import importlib

import pytest

#: (old module, name, new module)
MOVED = [
    (
        "slipkit.train.tasks.force",
        "FingerDirection",
        "slipkit.families.biotac.direction_task",
    ),
]


@pytest.mark.parametrize(("old", "name", "new"), MOVED)
def test_old_path_gives_the_same_class(old: str, name: str, new: str) -> None:
    """getattr on the old module (what pickle and Hydra's _target_ do) returns the class."""
    cls = getattr(importlib.import_module(new), name)
    assert cls is getattr(importlib.import_module(old), name)


def test_an_unknown_name_is_still_an_attribute_error() -> None:
    """The old module's lazy lookup does not invent names."""
    mod = importlib.import_module("slipkit.train.tasks.force")
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        mod.Nope  # noqa: B018
