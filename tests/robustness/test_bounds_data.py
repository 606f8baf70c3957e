"""Data a command cannot learn from is refused in one line naming it, exit 2."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from slipkit.cli import main
from slipkit.data import save_dataset
from slipkit.data.importers import read_csv_dataset


@pytest.fixture(autouse=True)
def _sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative outputs and internal-error logs land under tmp_path only."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SLIPKIT_LOG_DIR", str(tmp_path / "logs"))
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)


def one_class_dataset(root: Path) -> Path:
    """Six trials of two channels at 300 Hz, every one of class 'linear'."""
    rng = np.random.default_rng(0)
    (root / "csv").mkdir()
    for i in range(6):
        rows = "".join(
            f"{a:.3f},{b:.3f},linear,o{i % 3}\n" for a, b in rng.normal(size=(60, 2))
        )
        (root / "csv" / f"tr{i}.csv").write_text("a,b,slip_class,object\n" + rows)
    ds = read_csv_dataset(
        root / "csv",
        sensor="generic",
        rate_hz=300.0,
        label_columns=["slip_class"],
        group_columns=["object"],
    )
    return save_dataset(ds, root / "ds")


def test_training_on_one_class_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """slipkit train on a dataset whose class label has one class is one line naming it, exit 2, no run."""
    ds = one_class_dataset(tmp_path)
    capsys.readouterr()
    code: Any = 0
    try:
        main(
            [
                "train",
                f"dataset.path={ds}",
                "task=window_slip_type",
                "task.stream=signal",
                "task.window=10",
                "task.hop=5",
                "task.onset_label=null",
                "task.dynamics=null",
                "task.first_frame_control=false",
                "model=window_stats_lr",
                "model._args_.0.n_channels=2",
                f"run_dir={tmp_path / 'run'}",
            ]
        )
    except SystemExit as exc:
        code = exc.code
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert (
        2,
        [
            "slipkit train: error: task.label=slip_class: dataset 'csv' has one class "
            "'linear' in its 6 trials; a classifier needs trials of at least two classes"
        ],
        False,
    ) == (code, err, (tmp_path / "run").exists())
