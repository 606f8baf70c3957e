"""slipkit: train, compare and deploy tactile slip detectors.

The package root stays import-light on purpose: the gripper-PC runtime
(``slipkit.runtime``) must import without torch, scikit-learn or Hydra.
"""

from __future__ import annotations

from pathlib import Path

__version__ = "0.1.0"

__all__ = ["__version__", "config_dir"]


def config_dir() -> Path:
    """Return the folder holding slipkit's Hydra config tree.

    An installed wheel carries ``configs/`` as ``slipkit/configs``; an editable
    install (a checkout) reads the top-level ``configs/`` directly, so there is
    one source of every default either way.
    """
    packaged = Path(__file__).resolve().parent / "configs"
    if packaged.is_dir():
        return packaged
    checkout = Path(__file__).resolve().parents[2] / "configs"
    if checkout.is_dir():
        return checkout
    raise FileNotFoundError(
        f"slipkit's config tree is missing: looked for {packaged} and {checkout}"
    )
