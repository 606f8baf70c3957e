"""slipkit demo: the whole pipeline, simulate -> compare -> export -> replay -> report."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.demo import demo_main


def _run(tmp_path: Path, overrides: list[str]) -> Path:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(
            config_name="demo",
            overrides=[
                "quick=true",
                "progress=false",
                f"out={tmp_path / 'demo'}",
                f"data_root={tmp_path / 'no-real-data'}",
                *overrides,
            ],
        )
        return demo_main(cfg)


def test_demo_smoke_two_families(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two families end to end: the index links each report, the best bundle is written, path printed last."""
    report = _run(tmp_path, ["~comparisons", "+comparisons={tactip: [], fsr: []}"])
    assert tmp_path / "demo" / "report.md" == report
    text = report.read_text()
    for family in ("tactip", "fsr"):
        assert f"compare/{family}/report.md" in text
        assert (tmp_path / "demo" / "compare" / family / "report.md").is_file()
        assert (tmp_path / "demo" / "exports" / family / "manifest.json").is_file()
    assert str(report) == capsys.readouterr().out.strip().splitlines()[-1]


@pytest.mark.slow
def test_demo_quick_end_to_end(tmp_path: Path) -> None:
    """quick=true runs every simulated family; without real data dos_real is left out."""
    report = _run(tmp_path, [])
    text = report.read_text()
    for family in (
        "tactip",
        "biotac_force",
        "biotac_slip_type",
        "fsr",
        "sliptack",
        "davis",
    ):
        assert f"compare/{family}/report.md" in text
    assert "compare/dos_real" not in text
