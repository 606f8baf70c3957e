"""Which heavy libraries are loaded: the runtime's promise is numpy + onnxruntime only.

:func:`heavy_modules_loaded` is what ``slipkit-run --report-modules`` prints; tests
(and a fresh-venv install test of ``slipkit[runtime]``) assert it returns nothing after
a bundle has run.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable

#: Top-level packages a gripper PC must never need: the training stack and its helpers.
HEAVY_MODULES: tuple[str, ...] = (
    "hydra",
    "joblib",
    "matplotlib",
    "omegaconf",
    "onnx",
    "optuna",
    "pandas",
    "pyarrow",
    "scipy",
    "skl2onnx",
    "sklearn",
    "skorch",
    "torch",
)


def heavy_modules_loaded(modules: Iterable[str] | None = None) -> list[str]:
    """Sorted names from :data:`HEAVY_MODULES` among the loaded modules.

    Parameters
    ----------
    modules : iterable of str, optional
        Module names to inspect (dotted names allowed); ``sys.modules`` by default.
    """
    names = sys.modules if modules is None else modules
    top = {name.partition(".")[0] for name in names}
    return sorted(top.intersection(HEAVY_MODULES))
