"""Build slipkit's wheel for tests that check what it ships or install it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def build_wheel(dest: Path) -> Path:
    """Build the wheel into ``dest`` as `make wheel` does (no deps, no isolation); return its path."""
    done = subprocess.run(
        [
            *(sys.executable, "-m", "pip", "wheel"),
            *("--no-deps", "--no-build-isolation", "-q", "-w", str(dest), str(ROOT)),
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=900,
    )
    assert 0 == done.returncode, done.stderr[-3000:]
    (wheel,) = Path(dest).glob("slipkit-*.whl")
    return wheel
