"""`pip install 'slipkit[runtime]'` on a fresh venv runs a bundle with numpy + onnxruntime only."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from tests.runtime.helpers import (
    DOS_CLASSES,
    dos_like_bundle,
    pin_bundle,
    run_cli_reporting_modules,
)
from tests.wheel import build_wheel

from slipkit.runtime.modules import heavy_modules_loaded

ROOT = Path(__file__).resolve().parents[2]


def _run(
    *cmd: str, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        cmd, capture_output=True, text=True, check=False, timeout=900, env=env
    )
    assert 0 == done.returncode, f"{' '.join(cmd)}\n{done.stderr[-3000:]}"
    return done


@pytest.mark.slow
def test_runtime_extra_installs_and_runs_without_the_training_stack(
    tmp_path: Path,
) -> None:
    """A fresh venv with slipkit[runtime] holds no torch/sklearn/hydra/pandas and runs a bundle."""
    wheel = build_wheel(tmp_path / "wheel")
    venv = tmp_path / "venv"
    _run(sys.executable, "-m", "venv", str(venv))
    python = str(venv / "bin" / "python")
    _run(python, "-m", "pip", "install", "-q", f"{wheel}[runtime]")
    installed = _run(python, "-m", "pip", "list", "--format=freeze").stdout.lower()
    names = {line.split("==")[0] for line in installed.splitlines()}
    assert set() == names & {"torch", "scikit-learn", "hydra-core", "pandas", "scipy"}
    assert {"numpy", "onnxruntime"} <= names

    summary, imported = run_cli_reporting_modules(
        python, pin_bundle(tmp_path / "bundles"), tmp_path / "s.json"
    )
    assert [] == heavy_modules_loaded(imported)
    assert [] == summary["heavy_modules_loaded"]
    assert 0 < summary["decisions"]
    assert (venv / "bin" / "slipkit-run").is_file()

    # A DoS-like multi-class bundle (7 classes, slip = any direction, 10 ms frame).
    dos = dos_like_bundle(tmp_path / "bundles")
    done = _run(
        str(venv / "bin" / "slipkit-run"),
        str(dos),
        "--json",
        str(tmp_path / "dos.json"),
    )
    dos_summary = json.loads((tmp_path / "dos.json").read_text())
    assert list(DOS_CLASSES) == list(dos_summary["decisions_by_class"])
    # The latency verdict is reported, not asserted: tests never assert wall-clock times
    # (a loaded CI machine may miss a real bundle's budget).
    assert (10.0, True, True) == (
        dos_summary["budget_ms"]["frame_period"],
        isinstance(dos_summary["within_budget"], bool),
        "p99" in done.stdout,
    )


@pytest.mark.slow
def test_offline_install_from_a_wheelhouse_runs_a_bundle(tmp_path: Path) -> None:
    """`make wheelhouse`'s recipe: a fresh venv installs slipkit with --no-index from it and runs a bundle."""
    import numpy
    import onnxruntime

    house = tmp_path / "wheelhouse"
    # The wheel, as `make wheel` builds it.
    build_wheel(house)
    # The runtime's dependencies at the versions tested here, as `make wheelhouse`
    # downloads them (this machine reaches PyPI; the gripper PC need not).
    _run(
        sys.executable,
        "-m",
        "pip",
        "download",
        "-q",
        "--only-binary=:all:",
        "-d",
        str(house),
        f"numpy=={numpy.__version__}",
        f"onnxruntime=={onnxruntime.__version__}",
    )
    venv = tmp_path / "venv"
    _run(sys.executable, "-m", "venv", str(venv))
    python = str(venv / "bin" / "python")
    # Offline: no index, and none of this machine's pip configuration (its find-links
    # and extra indexes), so every file must come from the wheelhouse.
    offline = {k: v for k, v in os.environ.items() if not k.startswith("PIP_")}
    offline["PIP_CONFIG_FILE"] = os.devnull
    _run(
        python,
        "-m",
        "pip",
        "install",
        "-q",
        "--no-index",
        "--find-links",
        str(house),
        "slipkit",
        env=offline,
    )
    installed = _run(python, "-m", "pip", "list", "--format=freeze").stdout.lower()
    names = {line.split("==")[0] for line in installed.splitlines()}
    assert {"slipkit", "numpy", "onnxruntime"} <= names
    assert set() == names & {"torch", "scikit-learn", "hydra-core", "pandas", "scipy"}

    bundle = pin_bundle(tmp_path / "bundles")
    _run(
        str(venv / "bin" / "slipkit-run"),
        str(bundle),
        "--replay",
        str(bundle / "replay.npz"),
        "--json",
        str(tmp_path / "s.json"),
    )
    summary = json.loads((tmp_path / "s.json").read_text())
    # Latency is reported, not asserted (tests never assert wall-clock times).
    assert (True, 79) == (
        isinstance(summary["within_budget"], bool),
        summary["decisions"],
    )

    # Cold start in the runtime-only venv (docs/deploy.md quotes this benchmark).
    (tmp_path / "tmp").mkdir()
    bench_env = {**os.environ, "TMPDIR": str(tmp_path / "tmp")}  # its bundles go here
    bench = _run(
        sys.executable,
        str(ROOT / "benchmarks" / "bench_cold_start.py"),
        "--python",
        python,
        "--repeats",
        "3",
        env=bench_env,
    )
    print(bench.stdout)
    rows = [
        line.split()[2]
        for line in bench.stdout.splitlines()
        if "first decision" in line
    ]
    assert ["fsr_linear", "biotac_mlp", "tactip_rbf"] == rows
