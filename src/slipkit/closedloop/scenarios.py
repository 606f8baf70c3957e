"""The closed-loop scenario registry: how a sensor family plugs into ``slipkit closedloop``.

The command (:mod:`slipkit.closedloop.commands`) and the trial driver
(:func:`slipkit.closedloop.run.run_detector`) are generic: they train and export the
detectors, build the scene, loop over seeds, conditions and trials, and summarise the
:class:`~slipkit.closedloop.run.Outcome` rows. Everything family-specific lives in one
*scenario* object: the conditions grid, the check of the plant parameters, and one trial
(draw the object from the trial's generator, build the plant, map the plant's state to a
sensor frame with the scene's effects, run the paper's controller on the detector's
decisions, and report the outcome).

How a family registers
----------------------
1. Write ``src/slipkit/families/<family>/scenario.py`` (listed in
   ``slipkit.families.PLUGIN_MODULES["scenarios"]``) or ``src/slipkit/closedloop/<family>.py``
   with a class that satisfies :class:`ClosedLoopScenario` and decorate it with
   ``@register_scenario("<family>")``::

       from slipkit.closedloop.scenarios import register_scenario

       @register_scenario("sliptack")
       class SlipTackScenario:
           condition_label = "pull speed (mm/s)"

           def check(self, scen, scene): ...       # refuse bad plant parameters (SlipkitError)
           def conditions(self, scen): ...         # list[float]: the grid, one value per condition
           def run_trial(self, scene, detector, plant, *, seed, condition_index,
                         trial, condition): ...    # -> Outcome

2. Write ``configs/closedloop/<family>.yaml`` with ``name: <family>`` (or any name plus
   ``family: <family>``), ``scene``, ``plant``, ``trials_per_speed``, ``train_trials``,
   ``runs`` and ``detectors`` (see ``configs/closedloop/tactip.yaml``) and whatever the
   scenario's ``conditions`` reads.

Nothing else: :func:`get_scenario` imports the family folders' scenario modules, or
``slipkit.closedloop.<family>``, on first use, which runs the decorator, so ``commands.py`` and ``run.py`` need no edit.

Contract of ``run_trial``: draw everything from
``numpy.random.default_rng([seed, condition_index, trial])`` (so every detector meets the
same objects and noise), call ``detector.reset()`` first, and per frame call
``detector.decide(state, frame)`` with ``frame`` a zero-argument callable building the
sensor frame of the plant's *current* state (only detectors reading the sensor pay for
it); ``state`` exposes ``t`` (s), ``onset_s`` (the plant's slip onset, NaN before) for
the oracle bound.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, runtime_checkable

import numpy as np

import slipkit.families as _families
from slipkit._registry import Registry
from slipkit.errors import SlipkitError

if TYPE_CHECKING:
    from omegaconf import DictConfig

    from slipkit.closedloop.detectors import Detector
    from slipkit.closedloop.run import Outcome
    from slipkit.sim.core import Scene


@runtime_checkable
class ClosedLoopScenario(Protocol):
    """One family's closed-loop scenario: conditions, plant check, one trial.

    Attributes
    ----------
    condition_label : str
        Header of the per-condition table (e.g. ``"speed (mm/s)"``), with its unit.
    """

    condition_label: str

    def check(self, scen: DictConfig, scene: Scene) -> None:
        """Refuse a scenario or scene this family cannot run (a ``SlipkitError`` naming the field)."""

    def conditions(self, scen: DictConfig) -> list[float]:
        """The grid of conditions (one number each, in ``condition_label``'s unit)."""

    def run_trial(
        self,
        scene: Scene,
        detector: Detector,
        plant: Mapping[str, Any],
        *,
        seed: int,
        condition_index: int,
        trial: int,
        condition: float,
    ) -> Outcome:
        """One trial with ``detector`` in the loop."""


_T = TypeVar("_T")

#: Registered scenario classes by family name.
SCENARIOS: Registry[str, type] = Registry(
    "closed-loop scenario", error=ValueError, key_type=str
)


def _span(value: Any) -> tuple[float, float]:
    """A plant parameter given as one value or ``[lo, hi]``, as ``(lo, hi)``."""
    items = list(value) if isinstance(value, list | tuple) else [value, value]
    return float(items[0]), float(items[-1])


def _draw(rng: np.random.Generator, value: Any) -> float:
    """One draw of a plant parameter: the value, or uniform in ``[lo, hi]``."""
    lo, hi = _span(value)
    return lo if lo == hi else float(rng.uniform(lo, hi))


def plant_params(scen: DictConfig) -> dict[str, Any]:
    """The scenario's ``plant:`` mapping as a plain dict (one error when it is not a mapping)."""
    from omegaconf import OmegaConf

    plain = OmegaConf.to_container(scen.plant, resolve=True)
    if not isinstance(plain, dict):
        raise SlipkitError("closedloop.plant: expected a mapping of plant parameters")
    return {str(k): v for k, v in plain.items()}


def register_scenario(name: str) -> Callable[[type[_T]], type[_T]]:
    """Class decorator: register a :class:`ClosedLoopScenario` under ``name``."""

    def deco(cls: type[_T]) -> type[_T]:
        return SCENARIOS.register(name, cls)

    return deco


def get_scenario(family: str) -> ClosedLoopScenario:
    """A new scenario object for ``family`` (family folders' scenarios,
    ``slipkit.families.PLUGIN_MODULES["scenarios"]``, or ``slipkit.closedloop.<family>``,
    imported on first use)."""
    if not family.isidentifier():
        raise SlipkitError(
            f"closedloop.family={family!r}: expected a Python identifier (the module "
            "slipkit.closedloop.<family>)"
        )
    if family not in SCENARIOS:
        _families.load_plugins("scenarios")
    if family not in SCENARIOS:
        try:
            importlib.import_module(f"slipkit.closedloop.{family}")
        except ModuleNotFoundError as exc:
            if exc.name != f"slipkit.closedloop.{family}":
                raise
    cls = SCENARIOS.get(family)
    if cls is None:
        raise SlipkitError(
            f"closedloop.family={family}: no registered closed-loop scenario; "
            f"registered: {', '.join(sorted(SCENARIOS)) or 'none'}"
        )
    scenario = cls()
    if not isinstance(scenario, ClosedLoopScenario):
        raise TypeError(f"{cls.__name__} does not satisfy ClosedLoopScenario")
    return scenario
