"""The task contract: how an experiment turns a Dataset into fitted, scored estimators.

A *model* (``configs/model/*.yaml``) is a scikit-learn estimator and knows nothing of
datasets. A *task* (``configs/task/*.yaml``) is the recipe around it: which streams
and labels become ``X`` and ``y``, how the dataset is split (by trial, by group, by
30 s block), which metrics are reported, and which tables and plots are written.
``slipkit train`` calls :meth:`Task.fit`; ``slipkit evaluate`` calls
:meth:`Task.evaluate` with the fitted model on a dataset the model never saw.

Analytic detectors are models too: their task's ``fit`` lets them choose a threshold
on the training side and scores them like any learned model.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

import slipkit.families as _families
from slipkit._registry import Registry
from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError


class ObjectiveMissing(SlipkitError, KeyError):
    """The metrics lack the task's objective (e.g. too few training trials for the
    validation CV): a one-line CLI error, and a KeyError for callers that probe."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


@dataclass
class TaskResult:
    """What :meth:`Task.fit` hands back to ``slipkit train``.

    Attributes
    ----------
    model : estimator
        The fitted estimator saved in the run folder (``model.joblib``).
    metrics : dict
        JSON-able metrics; must hold the task's :attr:`Task.objective` key.
    summary : list of str
        Lines printed at the end of the run (tables beside the papers' figures).
    """

    model: Any
    metrics: dict[str, Any]
    summary: list[str] = field(default_factory=list)


class Task(ABC):
    """One experiment's recipe: dataset -> (X, y) -> split -> fit -> metrics + files.

    Subclasses store their parameters in ``__init__`` (built by
    ``hydra.utils.instantiate`` from ``configs/task/*.yaml``) and implement
    :meth:`fit` and :meth:`evaluate`. Both may write tables (``.csv``/``.md``) and
    plots (``.png``) into ``out``; ``out`` is a temporary folder that becomes the run
    (or evaluation) folder only when the call returns.
    """

    #: key of the metrics dict (dots for nesting) returned to a Hydra sweeper. It must
    #: name a validation score computed on the training side only (group-aware CV by
    #: object or trial, ``validation.<metric>``), never the test split: a sweeper that
    #: ranks runs by it then selects without looking at the test data.
    objective: str = "accuracy"
    #: "maximize" or "minimize" (the sweeper's direction for :attr:`objective`)
    direction: str = "maximize"
    #: the estimator classes the task fits: ``slipkit compare`` refuses any other before
    #: anything trains (empty: no check)
    accepts: ClassVar[tuple[type, ...]] = ()
    #: classes refused even when accepted (an analytic detector is a classifier too)
    refuses: ClassVar[tuple[type, ...]] = ()
    #: what the task feeds its estimator, for that refusal (``{stream}``: the task's stream)
    feeds: ClassVar[str] = ""

    def estimator_rule(self) -> tuple[tuple[type, ...], tuple[type, ...], str] | None:
        """(accepted classes, refused classes, what the task feeds), or None: no check."""
        if not self.accepts:
            return None
        return (
            self.accepts,
            self.refuses,
            self.feeds.format(stream=repr(getattr(self, "stream", "?"))),
        )

    @abstractmethod
    def fit(self, model: Any, dataset: Dataset, *, seed: int, out: Path) -> TaskResult:
        """Split ``dataset``, fit ``model`` on the training side, score every side."""

    @abstractmethod
    def evaluate(self, model: Any, dataset: Dataset, *, out: Path) -> dict[str, Any]:
        """Score the fitted ``model`` on all of ``dataset`` (data it never saw)."""

    def headline(self, metrics: Mapping[str, Any]) -> list[str]:
        """Lines ``slipkit evaluate`` prints first: what the deployed estimator does
        (a detector's operating point); none by default."""
        return []

    def objective_value(
        self, metrics: Mapping[str, Any], name: str | None = None
    ) -> float:
        """The number named by :attr:`objective` (or ``name``) in ``metrics`` (dots
        descend)."""
        wanted = self.objective if name is None else name
        node: Any = metrics
        for key in wanted.split("."):
            if not isinstance(node, Mapping) or key not in node:
                raise ObjectiveMissing(
                    f"{type(self).__name__}: objective {wanted!r} not in metrics "
                    f"(keys: {sorted(metrics)})"
                )
            node = node[key]
        return float(node)


def jsonable(value: Any) -> Any:
    """``value`` with numpy scalars/arrays turned into plain JSON types; NaN -> None."""
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


#: analytic estimator classes family folders register (their tasks' modules, listed in
#: ``slipkit.families.PLUGIN_MODULES["tasks"]``), by class
_ANALYTIC: Registry[type, type] = Registry(
    "analytic estimator", error=SlipkitError, key_type=type
)


def register_analytic_estimator(cls: type) -> type:
    """Mark ``cls`` as an analytic estimator that learned-model tasks refuse (it reads a
    stream inside its own task); returns ``cls``."""
    return _ANALYTIC.register(cls, cls)


def analytic_estimators() -> tuple[type, ...]:
    """The analytic estimators a learned-model task refuses (they read a stream inside
    their own task): stream detectors and what family folders register with
    :func:`register_analytic_estimator`."""
    from slipkit.baselines.base import StreamDetector

    _families.load_plugins("tasks")
    return (StreamDetector, *_ANALYTIC)
