"""A family shipped as its own package adds runtime ops through an entry point."""

from __future__ import annotations

import importlib.metadata
import sys
from pathlib import Path

import pytest

from slipkit.runtime import ops
from slipkit.runtime.preprocessing import OPS


def _fake_entry_points(
    monkeypatch: pytest.MonkeyPatch, eps: list[importlib.metadata.EntryPoint]
) -> None:
    real = importlib.metadata.entry_points

    def entry_points(**kw: str) -> object:
        if kw.get("group") == ops.ENTRY_POINT_GROUP:
            return eps
        return real(**kw)

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)


def test_an_installed_package_registers_its_op_and_a_broken_one_is_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "labfam_ops.py").write_text(
        "import numpy as np\n"
        "from slipkit.runtime.preprocessing import register_op\n"
        "@register_op('labfam_scale')\n"
        "def _build(f, shape):\n"
        "    k = f.number('k')\n"
        "    return lambda w: np.asarray(w) * k\n",
        encoding="utf-8",
    )
    (tmp_path / "labfam_broken.py").write_text("import no_such_module\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    group = ops.ENTRY_POINT_GROUP
    _fake_entry_points(
        monkeypatch,
        [
            importlib.metadata.EntryPoint("labfam", "labfam_ops", group),
            importlib.metadata.EntryPoint("broken", "labfam_broken", group),
        ],
    )
    try:
        with pytest.warns(RuntimeWarning, match=r"'broken' \(labfam_broken\).*no_such"):
            loaded = ops.load_entry_points()
        assert loaded == ["labfam"]
        assert "labfam_scale" in OPS
        # a second call imports nothing twice (a second registration would be refused)
        with pytest.warns(RuntimeWarning):
            assert ops.load_entry_points() == ["labfam"]
    finally:
        if "labfam_scale" in OPS:
            OPS.unregister("labfam_scale")
        for name in ("labfam_ops", "labfam_broken"):
            sys.modules.pop(name, None)
