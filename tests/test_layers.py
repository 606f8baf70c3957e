"""The import layers in pyproject.toml ([tool.importlinter]) hold: no stage imports a stage
above it, and the gripper-PC runtime imports numpy, onnxruntime and the standard library only."""

from __future__ import annotations

import os
from pathlib import Path

import importlinter.cli as importlinter_cli
import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_are_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    """`lint-imports` exits 0 with every contract kept (a broken contract names the import)."""
    monkeypatch.chdir(ROOT)
    monkeypatch.syspath_prepend(str(ROOT / "src"))
    assert os.path.isfile("pyproject.toml")
    status = importlinter_cli.lint_imports(
        config_filename="pyproject.toml", no_cache=True, no_logo=True
    )
    assert 0 == status


def test_no_module_is_over_a_thousand_lines():
    """A module a newcomer reads stays under 1000 lines (split by concept when it grows)."""
    from pathlib import Path

    src = Path(__file__).resolve().parents[1] / "src" / "slipkit"
    lines = {
        str(p.relative_to(src)): len(p.read_text(encoding="utf-8").splitlines())
        for p in src.rglob("*.py")
    }
    long = {name: n for name, n in lines.items() if n > 1000}
    assert {} == long
