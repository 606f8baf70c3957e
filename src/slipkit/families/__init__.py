"""Sensor families: each family folder declares its parts; this module finds them.

A family is a sensor and what slipkit does with it: its simulated scenes and effects, its
tasks (the data recipes), its estimators' exporters, the deployers and comparison adapters
of its tasks, its comparison and closed-loop configs and its docs. Each lives in one folder,
``slipkit/families/<name>/``, whose ``__init__.py`` holds its record, ``FAMILY =
Family(...)`` (:class:`Family`: ``"module:attr"`` strings,
resolved on demand by :func:`resolve`). A family shipped as its own package registers the
same record under the entry-point group ``slipkit.families`` (the entry point names a
module holding ``FAMILY``, or the record itself). Adding a family therefore edits no
shared module: :data:`FAMILIES` is every folder's record and every entry point's, and
``tests/test_families.py`` checks each record is complete (each task has the comparison
adapter and deployer the record claims, each exporter module registers an exporter, each
scene and scenario resolves, each config and doc page exists).

Reading the records imports each family folder's ``__init__`` only, nothing of the
stages (a folder's ``__init__`` imports :class:`Family` from here, defined before the
folders are read). :data:`PLUGIN_MODULES` gathers the records' plug-in modules by kind, and the stage
owning a kind imports them by name (:func:`load_plugins`), never statically.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import pkgutil
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from slipkit.errors import SlipkitError

#: the generic tasks a family may train, deploy and compare through
DETECTION_TASK = "slipkit.train.tasks.detection:StreamDetection"
WINDOW_TASK = "slipkit.train.tasks.slip_type:WindowClassification"
#: the kinds of plug-in a family registers besides its exporters
PLUGIN_KINDS = ("deployers", "adapters", "scenarios", "effects", "tasks")


@dataclass(frozen=True)
class Family:
    """The parts of one sensor family.

    Parameters
    ----------
    name : str
        The family (``sliptack``).
    sensor : str
        Its ``configs/deploy/<sensor>.yaml`` (frame period and latency budget).
    tasks : tuple of str
        ``"module:Class"`` of each task that trains on the family's data.
    deploys : tuple of str
        The tasks (as in ``tasks``) whose runs ``slipkit export`` turns into bundles.
    compares : tuple of str
        The tasks ``slipkit compare`` reads through an adapter.
    exporters : tuple of str
        Modules whose import registers the family's estimators' exporters.
    scenes : tuple of str
        ``configs/scene/<name>.yaml`` of the simulated scenes (empty: real data only).
    comparisons : tuple of str
        ``configs/comparison/<name>.yaml``.
    scenario : str or None
        ``configs/closedloop/<name>.yaml`` and the registered closed-loop scenario.
    docs : tuple of str
        The doc pages (paths under ``docs/``).
    detectors : tuple of str
        Modules of a family folder whose estimators train as detectors (the ``detector:``
        slot of a train config, as ``slipkit.baselines``'s): :func:`detector_module`.
    plugins : mapping of str to tuple of str
        Modules whose import registers the family's other plug-ins, by kind
        (``deployers``, ``adapters``, ``scenarios``, ``effects``, ``tasks``):
        :data:`slipkit.families.PLUGIN_MODULES`.
    """

    name: str
    sensor: str
    tasks: tuple[str, ...]
    deploys: tuple[str, ...]
    compares: tuple[str, ...]
    exporters: tuple[str, ...]
    scenes: tuple[str, ...] = ()
    comparisons: tuple[str, ...] = ()
    scenario: str | None = None
    docs: tuple[str, ...] = field(default_factory=tuple)
    detectors: tuple[str, ...] = ()
    plugins: Mapping[str, tuple[str, ...]] = field(default_factory=dict)


#: the entry-point group a family shipped as its own package registers under
ENTRY_POINT_GROUP = "slipkit.families"


def _record_of(obj: Any, where: str) -> Family:
    record = obj if isinstance(obj, Family) else getattr(obj, "FAMILY", None)
    if not isinstance(record, Family):
        raise SlipkitError(
            f"{where}: a sensor family declares FAMILY = slipkit.families.Family(...) "
            f"(found {type(record).__name__})"
        )
    return record


def _folder_records() -> Iterable[tuple[str, Family]]:
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.ispkg and not info.name.startswith("_"):
            module = importlib.import_module(f"{__name__}.{info.name}")
            yield f"slipkit/families/{info.name}", _record_of(module, module.__name__)


def _entry_point_records() -> Iterable[tuple[str, Family]]:
    for ep in sorted(
        importlib.metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name
    ):
        where = f"entry point {ep.name!r} ({ep.value}) of group {ENTRY_POINT_GROUP!r}"
        yield where, _record_of(ep.load(), where)


def discover(
    sources: Iterable[tuple[str, Family]] | None = None,
) -> dict[str, Family]:
    """Every family's record by name: the family folders', then the entry points'.

    Two records of one name are refused, naming both places.
    """
    found: dict[str, Family] = {}
    origin: dict[str, str] = {}
    pairs = (
        sources
        if sources is not None
        else [*_folder_records(), *_entry_point_records()]
    )
    for where, record in pairs:
        if record.name in found:
            raise SlipkitError(
                f"{where}: sensor family {record.name!r} is already declared by "
                f"{origin[record.name]}"
            )
        found[record.name], origin[record.name] = record, where
    return found


def plugin_modules(families: Mapping[str, Family]) -> dict[str, tuple[str, ...]]:
    """The records' plug-in modules by kind (each once, in the records' order).

    ``exporters`` holds the families' exporter modules outside slipkit's own stages
    (``slipkit.export`` imports its generic exporters itself).
    """
    kinds: dict[str, list[str]] = {"exporters": [], **{k: [] for k in PLUGIN_KINDS}}
    for f in families.values():
        kinds["exporters"] += [
            m
            for m in f.exporters
            if m.startswith(__name__ + ".") or not m.startswith("slipkit.")
        ]
        for kind, modules in f.plugins.items():
            if kind not in kinds:
                raise SlipkitError(
                    f"sensor family {f.name!r}: plugins kind {kind!r} is not one of "
                    f"{sorted(kinds)}"
                )
            kinds[kind] += modules
    return {k: tuple(dict.fromkeys(v)) for k, v in kinds.items()}


#: every family's record by name (:func:`discover`)
FAMILIES: dict[str, Family] = discover()

#: modules whose import registers the families' plug-ins, by kind; the stage that owns
#: the kind imports them by name (:func:`load_plugins`) at its entry or first lookup:
#:
#: * ``exporters`` -- ``slipkit.export`` (exporters by estimator class);
#: * ``deployers`` -- :func:`slipkit.export.deploy.deployer_for` (deployers by task class);
#: * ``adapters`` -- :func:`slipkit.compare.adapters.adapt` (comparison adapters);
#: * ``scenarios`` -- :func:`slipkit.closedloop.scenarios.get_scenario`;
#: * ``effects`` -- ``slipkit.sim.effects`` (scene effects by name);
#: * ``tasks`` -- :func:`slipkit.train.task.analytic_estimators` (the task modules register
#:   the analytic estimators learned-model tasks refuse).
#:
#: Scenes, tasks and estimators are built from ``configs/`` by their ``_target_`` paths.
PLUGIN_MODULES: dict[str, tuple[str, ...]] = plugin_modules(FAMILIES)


def resolve(ref: str) -> Any:
    """The object a ``"module:attr"`` string names (the module alone without ``:attr``)."""
    module, _, attr = ref.partition(":")
    mod = importlib.import_module(module)
    return getattr(mod, attr) if attr else mod


def detector_module(module: str) -> bool:
    """Whether the estimators of ``module`` train as detectors (the ``detector:`` slot of a
    train config, analytic unless the class says otherwise): ``slipkit.baselines`` and the
    modules families list as ``detectors``."""
    return module.startswith("slipkit.baselines.") or any(
        module in f.detectors for f in FAMILIES.values()
    )


def load_plugins(kind: str) -> None:
    """Import every family folder's modules of ``kind`` (registering what they hold)."""
    for module in PLUGIN_MODULES.get(kind, ()):
        importlib.import_module(module)


__all__ = [
    "ENTRY_POINT_GROUP",
    "FAMILIES",
    "PLUGIN_MODULES",
    "Family",
    "detector_module",
    "discover",
    "load_plugins",
    "plugin_modules",
    "resolve",
]
