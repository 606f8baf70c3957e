"""What a comparison prints besides its table: no library warnings, slipkit's own warnings once."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

import slipkit.cli as cli
from slipkit.errors import SlipkitWarning
from slipkit.evaluate.aggregate import aggregate
from slipkit.models.svm import TacTipSVM


class _Meaningful(SlipkitWarning):
    """A stand-in for a warning about the data, raised on every fit."""


def test_aggregate_of_many_metrics_warns_nothing() -> None:
    """Folding 60 metrics over seeds raises no warning (pandas' fragmented-frame one before)."""
    rng = np.random.default_rng(0)
    df = pd.DataFrame(
        {
            "estimator": ["a", "a", "b", "b"],
            **{f"m{i}": rng.normal(size=4) for i in range(60)},
        }
    )
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        table = aggregate(df, ["estimator"])
    assert ([], (2, 2 + 3 * 60)) == ([str(w.message) for w in shown], table.shape)


@pytest.mark.slow
def test_a_small_compare_shows_no_library_warning_and_a_repeated_one_once(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A two-seed TacTip comparison (no tuned SVM) in-process: no PerformanceWarning or
    library UserWarning reaches the user; a slipkit warning raised on every SVM fit shows once."""
    fit = TacTipSVM.fit
    calls = []

    def warning_fit(self: Any, *args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        warnings.warn("the data breaks a convention", _Meaningful, stacklevel=2)
        return fit(self, *args, **kwargs)

    monkeypatch.setattr(TacTipSVM, "fit", warning_fit)
    monkeypatch.setattr(warnings, "onceregistry", {})
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")  # everything, unless slipkit filters it
        cli.main(
            [
                "compare",
                "comparison=tactip",
                "comparison.dataset.n_trials=4",
                "~comparison.estimators.svm_rbf_tuned",
                "seeds=[0,1]",
                f"out={tmp_path / 'tactip'}",
                "progress=false",
                "cost.max_frames=100",
                "cost.warmup=2",
            ]
        )
    library = [
        f"{w.category.__name__}: {w.message}"
        for w in shown
        if issubclass(w.category, UserWarning | pd.errors.PerformanceWarning)
        and not issubclass(w.category, SlipkitWarning)
    ]
    ours = [w for w in shown if issubclass(w.category, _Meaningful)]
    assert ([], 1, True) == (library, len(ours), len(calls) > 1)
