"""ONNX exporters: fitted estimators -> :class:`ExportedGraph` (graph + what it means).

Importing this package registers every exporter (one module per family, each
ending with its ``register_exporter`` call, as sklearn-onnx's converters):

* :mod:`slipkit.export.sklearn` -- every class skl2onnx converts, Pipelines included;
* :mod:`slipkit.export.torch` -- torch modules and skorch nets (legacy exporter);
* the family folders' exporters (``slipkit.families.PLUGIN_MODULES["exporters"]``, e.g.
  ``TacTipSVM`` as MatMul/Exp ops in :mod:`slipkit.families.tactip.export.svm`).

:func:`export` picks the exporter by the estimator's class (MRO walk) and
:func:`slipkit.export.parity.check_parity` compares the graph in onnxruntime with
the estimator. The export side needs the ``train`` extra (onnx, skl2onnx, torch);
the gripper-PC runtime only loads the resulting ``.onnx`` files.
"""

from __future__ import annotations

import importlib as _importlib

import slipkit.families as _families
from slipkit.export import detectors as _detectors  # noqa: F401  (registers exporters)
from slipkit.export import frame_gru as _frame_gru  # noqa: F401
from slipkit.export import generic as _generic  # noqa: F401
from slipkit.export import sklearn as _sklearn  # noqa: F401
from slipkit.export import torch as _torch  # noqa: F401
from slipkit.export import window_stats as _window_stats  # noqa: F401
from slipkit.export.parity import check_parity
from slipkit.export.pins import export_velocity_features
from slipkit.export.registry import (
    ExportedGraph,
    ExportError,
    NoExporterError,
    RuntimeSteps,
    StreamContext,
    export,
    exporter_for,
    register_exporter,
    register_runtime_steps,
)
from slipkit.export.sklearn import export_sklearn
from slipkit.export.torch import (
    export_skorch_estimator,
    export_torch_module,
    find_torch_parts,
)

# Every family's exporter modules (slipkit.families: the one table of a family's parts) and
# family folders' plug-ins; the modules imported above are imported once, not again.
for _module in sorted({e for f in _families.FAMILIES.values() for e in f.exporters}):
    _importlib.import_module(_module)
_families.load_plugins("exporters")

__all__ = [
    "ExportError",
    "ExportedGraph",
    "NoExporterError",
    "RuntimeSteps",
    "StreamContext",
    "check_parity",
    "export",
    "export_sklearn",
    "export_skorch_estimator",
    "export_torch_module",
    "export_velocity_features",
    "exporter_for",
    "find_torch_parts",
    "register_exporter",
    "register_runtime_steps",
]
