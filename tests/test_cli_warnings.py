"""The `slipkit` command shows each of slipkit's own warnings once per run, not once per fit."""

from __future__ import annotations

import warnings
from typing import Any

import pytest

import slipkit.cli as cli
from slipkit.data import save_dataset
from slipkit.errors import SlipkitWarning
from slipkit.families.sliptack.speed import FixedNormalForceWarning


def _warn_thrice(cfg: Any) -> None:
    for _ in range(3):
        # each fit of an estimator enters catch_warnings (scikit-learn does), which
        # resets the per-location registry: the default filter would show all three
        with warnings.catch_warnings():
            warnings.warn(
                "one fixed normal force", FixedNormalForceWarning, stacklevel=1
            )
    warnings.warn("another message", FixedNormalForceWarning, stacklevel=1)


def test_a_repeated_slipkit_warning_is_shown_once(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Any
) -> None:
    """Three identical FixedNormalForceWarnings in one `slipkit info` run print once; a new message prints too."""
    from tests.strategies import make_dataset

    path = save_dataset(make_dataset(n_trials=2), tmp_path / "ds")
    monkeypatch.setitem(
        cli.SUBCOMMANDS, "info", (f"{__name__}:_warn_thrice", "test stand-in")
    )
    monkeypatch.setattr(warnings, "onceregistry", {})
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")  # everything, unless the command filters it
        cli.main(["info", f"dataset={path}"])
    texts = [str(w.message) for w in shown]
    assert (1, 1, True) == (
        texts.count("one fixed normal force"),
        texts.count("another message"),
        issubclass(FixedNormalForceWarning, SlipkitWarning),
    )
