"""The kernel-approximation TacTip model (configs/model/tactip_nystroem.yaml) trains through the
TacTip task and is refused, in one line, by the TacTip frame exporter (no pin-feature graph)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from slipkit.cli import main


def test_nystroem_trains_and_export_names_why_it_cannot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit train model=tactip_nystroem` writes a scored run; `slipkit export` exits 2 naming the model."""
    run = tmp_path / "run"
    main(
        [
            "train",
            "experiment=tactip_svm",
            "model=tactip_nystroem",
            "dataset.n_trials=4",
            f"run_dir={run}",
        ]
    )
    metrics = json.loads((run / "metrics.json").read_text())
    assert ("Pipeline", True) == (
        metrics["params"]["estimator"],
        0.0 <= metrics["test"]["balanced_accuracy"] <= 1.0,
    )
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(["export", f"run={run}", f"out={tmp_path / 'bundle'}"])
    err = capsys.readouterr().err.strip().splitlines()
    assert (2, 1, False) == (
        exc.value.code,
        len(err),
        (tmp_path / "bundle").exists(),
    )
    assert "needs a TacTipSVM" in err[0]
    assert "Pipeline" in err[0]
