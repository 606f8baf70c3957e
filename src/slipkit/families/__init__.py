"""Sensor families: one record per family listing its parts, as ``"module:attr"`` strings.

A family is a sensor and what slipkit does with it: its simulated scenes and effects, its
tasks (the data recipes), its estimators' exporters, the deployers and comparison adapters
of its tasks, its comparison and closed-loop configs and its docs. :data:`FAMILIES` lists
them in one place so that a reader finds a family's parts without searching, and
``tests/test_families.py`` checks every record is complete: each task has the comparison
adapter and deployer the record claims, each exporter module registers an exporter, each
scene and scenario resolves, each config and doc page exists.

The records hold strings only, resolved on demand (:func:`resolve`), so this module imports
nothing of the stages and any stage may read it. A family packaged as one folder lives in
``slipkit/families/<name>/`` (``gelsight``, ``sliptack``, ``fsr``); :data:`PLUGIN_MODULES` names the
modules of such folders that register plug-ins when imported, by kind, and the stage owning a
kind imports them by name (:func:`load_plugins`), never statically.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any


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


_T = "slipkit.train.tasks."
_DETECT = _T + "detection:StreamDetection"
_WINDOWS = _T + "slip_type:WindowClassification"
_ST = "slipkit.families.sliptack."
_SLIPTACK_EXPORTERS = tuple(
    f"{_ST}export.{m}" for m in ("speed", "detector", "onset", "spectral", "torsion")
)
_FSR = "slipkit.families.fsr."
_FSR_EXPORTERS = (_FSR + "export.touch_slip", _FSR + "export.onset")

FAMILIES: dict[str, Family] = {
    f.name: f
    for f in (
        Family(
            name="tactip",
            sensor="tactip",
            tasks=(
                _T + "tactip:TacTipFrames",
                _T + "tactip_table:TacTipTable1",
                _DETECT,
            ),
            deploys=(_T + "tactip:TacTipFrames", _DETECT),
            compares=(_T + "tactip:TacTipFrames", _DETECT),
            exporters=("slipkit.export.svm", "slipkit.export.tactip_detector"),
            scenes=("tactip_gravity_drop", "tactip_gravity_drop_hard"),
            comparisons=("tactip",),
            scenario="tactip",
            docs=("simulation/tactip.md", "models/tactip.md"),
        ),
        Family(
            name="biotac",
            sensor="biotac",
            tasks=(
                _T + "force:ForceRegression",
                _T + "force_direction:FingerDirection",
                _WINDOWS,
                _T + "grasp:GraspStability",
                _DETECT,
            ),
            deploys=(_T + "force:ForceRegression", _WINDOWS, _DETECT),
            compares=(_T + "force:ForceRegression", _WINDOWS, _DETECT),
            exporters=(
                "slipkit.export.force",
                "slipkit.export.biotac_detectors",
                "slipkit.export.window_analytic",
                "slipkit.export.window_stats",
                "slipkit.export.generic",
                "slipkit.export.frame_gru",
            ),
            scenes=("biotac_force_probe", "biotac_lift_slip", "biotac_lift_slip_hard"),
            comparisons=("biotac_force", "biotac_slip", "biotac_slip_type", "dos_real"),
            scenario="biotac",
            docs=(
                "simulation/biotac.md",
                "baselines/biotac.md",
                "models/force.md",
                "models/slip_type.md",
            ),
        ),
        Family(
            name="fsr",
            sensor="fsr",
            tasks=(_DETECT,),
            deploys=(_DETECT,),
            compares=(_DETECT,),
            exporters=(*_FSR_EXPORTERS, "slipkit.export.generic"),
            scenes=("fsr_probe_slide", "fsr_probe_slide_hard"),
            comparisons=("fsr",),
            scenario="fsr",
            docs=("simulation/fsr.md", "baselines/fsr.md"),
            detectors=(_FSR + "touch_slip", _FSR + "onset"),
        ),
        Family(
            name="sliptack",
            sensor="sliptack",
            tasks=(_ST + "task:SlipTackSpeed", _ST + "task:SlipTackAccel", _DETECT),
            deploys=(_ST + "task:SlipTackSpeed", _DETECT),
            compares=(_ST + "task:SlipTackSpeed", _ST + "task:SlipTackAccel", _DETECT),
            exporters=_SLIPTACK_EXPORTERS,
            scenes=("sliptack_pull", "sliptack_pull_hard", "sliptack_drop"),
            comparisons=("sliptack", "sliptack_slip"),
            scenario="sliptack",
            docs=("simulation/sliptack.md", "baselines/sliptack.md"),
            detectors=tuple(_ST + m for m in ("speed", "accel", "onset", "torsion")),
        ),
        Family(
            name="davis",
            sensor="davis",
            tasks=(_T + "davis:DavisRelease",),
            deploys=(_T + "davis:DavisRelease",),
            compares=(_T + "davis:DavisRelease",),
            exporters=(
                "slipkit.export.davis",
                "slipkit.export.davis_onset",
                "slipkit.export.events",
            ),
            scenes=("davis_release", "davis_release_hard"),
            comparisons=("davis",),
            scenario="davis",
            docs=("simulation/davis.md", "baselines/davis.md"),
        ),
        Family(
            name="gelsight",
            sensor="gelsight",
            tasks=(_DETECT,),
            deploys=(_DETECT,),
            compares=(_DETECT,),
            exporters=("slipkit.families.gelsight.export",),
            scenes=("gelsight_grasp", "gelsight_grasp_setdown"),
            docs=("families/gelsight.md",),
        ),
    )
}

#: modules of family folders (``slipkit/families/<name>/``) whose import registers their
#: plug-ins, by kind; the stage that owns the kind imports them by name
#: (:func:`load_plugins`) at its entry or at its first lookup:
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
PLUGIN_MODULES: dict[str, tuple[str, ...]] = {
    "exporters": (
        "slipkit.families.gelsight.export",
        *_SLIPTACK_EXPORTERS,
        *_FSR_EXPORTERS,
    ),
    "deployers": (_ST + "deploy",),
    "adapters": (_ST + "adapter",),
    "scenarios": (_ST + "scenario", _FSR + "scenario"),
    "effects": (_ST + "effects", _FSR + "effects", "slipkit.families.gelsight.effects"),
    "tasks": (_ST + "task",),
}


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
    "FAMILIES",
    "PLUGIN_MODULES",
    "Family",
    "detector_module",
    "load_plugins",
    "resolve",
]
