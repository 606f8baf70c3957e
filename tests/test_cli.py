"""The `slipkit` command: subcommand dispatch, Hydra overrides, clear errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from tests.strategies import make_dataset

from slipkit.cli import SUBCOMMANDS, main
from slipkit.data import save_dataset


def test_usage_lists_every_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    """`slipkit` alone prints the usage with every working subcommand."""
    main([])
    out = capsys.readouterr().out
    for name in SUBCOMMANDS:
        assert name in out


def test_unknown_subcommand_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    """An unknown subcommand exits with status 2 and names it."""
    with pytest.raises(SystemExit) as exc:
        main(["fly"])
    assert 2 == exc.value.code
    assert "unknown subcommand 'fly'" in capsys.readouterr().err


def test_info_prints_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit info dataset=...` prints trials, streams with rates and class counts."""
    path = save_dataset(make_dataset(n_trials=4), tmp_path / "ds")
    main(["info", f"dataset={path}"])
    out = capsys.readouterr().out
    assert "trials    4" in out
    assert "300 Hz" in out
    assert "linear: 2, rotational: 2" in out


def test_info_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`json=true` prints a machine-readable summary."""
    import json

    path = save_dataset(make_dataset(n_trials=4), tmp_path / "ds")
    main(["info", f"dataset={path}", "json=true"])
    info = json.loads(capsys.readouterr().out)
    assert 4 == info["trials"]
    assert 300.0 == info["streams"]["force"]["rate_hz"]


def test_bad_dataset_gives_clear_error_not_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A folder that is not a dataset exits 2 with the file named and no traceback."""
    with pytest.raises(SystemExit) as exc:
        main(["info", f"dataset={tmp_path}"])
    assert 2 == exc.value.code
    err = capsys.readouterr().err
    assert "manifest.json: missing" in err
    assert "Traceback" not in err


def test_console_script_runs_in_a_subprocess(tmp_path: Path) -> None:
    """The installed `slipkit` entry point runs `info` end to end in a fresh process."""
    path = save_dataset(make_dataset(n_trials=2), tmp_path / "ds")
    exe = Path(sys.executable).with_name("slipkit")
    result = subprocess.run(
        [str(exe), "info", f"dataset={path}"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert 0 == result.returncode, result.stderr
    assert "sensor    biotac" in result.stdout


def test_simulate_with_every_effect_removed(tmp_path: Path) -> None:
    """A scene with its effects removed on the command line still simulates (backbone only)."""
    out = tmp_path / "pull"
    main(
        [
            "simulate",
            "scene=sliptack_pull",
            "n_trials=1",
            "~scene.effects",
            f"out={out}",
            "progress=false",
            "summary=false",
        ]
    )
    from slipkit.data import load_dataset

    assert [] == load_dataset(out).provenance["effects"]


def test_out_of_range_scene_parameter_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A model parameter out of range exits 2 with the key named and no traceback."""
    with pytest.raises(SystemExit) as exc:
        main(
            [
                "simulate",
                "scene=sliptack_pull",
                "scene.model.rate_hz=-5",
                f"out={tmp_path / 'x'}",
            ]
        )
    assert 2 == exc.value.code
    err = capsys.readouterr().err
    assert "rate_hz" in err
    assert "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_multirun_with_cfg_is_a_one_line_usage_error(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`-m` with `--cfg` (Hydra allows one mode) exits 2 naming both flags, not an internal error."""
    with pytest.raises(SystemExit) as exc:
        main(["train", "-m", "experiment=fsr_roc", "--cfg", "hydra"])
    err = capsys.readouterr().err.strip()
    assert (2, 1) == (exc.value.code, len(err.splitlines()))
    assert "--multirun and --cfg cannot be combined" in err
