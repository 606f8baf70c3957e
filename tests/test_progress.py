"""Fold progress lines: on stderr in `slipkit train`, quiet inside a comparison."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.compare.commands import compare_main
from slipkit.progress import progress_line, quiet_progress


def test_progress_lines_print_unless_quieted(
    capsys: pytest.CaptureFixture[str],
) -> None:
    progress_line("fold 1/3 done")
    with quiet_progress():
        progress_line("fold 2/3 done")
        with quiet_progress():
            progress_line("fold 3/3 done")
    progress_line("step 2")
    assert "fold 1/3 done\nstep 2\n" == capsys.readouterr().err


def test_a_comparison_prints_no_fold_lines(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The SlipTack speed task validates in folds; inside `slipkit compare` (one progress
    bar per run) its fold lines stay off the terminal, the verdict still prints."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="compare",
            overrides=[
                "comparison=sliptack",
                "comparison.dataset.n_trials=4",
                *(
                    f"~comparison.estimators.{e}"
                    for e in (
                        "paper_form",
                        "calibrated",
                        "spectral_gbr",
                        "onset",
                        "onset_logistic",
                    )
                ),
                f"out={tmp_path / 'sliptack'}",
                "progress=false",
                "cost.max_frames=100",
                "cost.warmup=2",
            ],
        )
    compare_main(cfg)
    out = capsys.readouterr()
    assert "fold" not in out.err
    assert "exact" in out.out
