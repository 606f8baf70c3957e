"""The part every closed-loop scenario shares: the scene check and the conditions grid.

A family's scenario (``slipkit/families/<family>/scenario.py``) subclasses
:class:`GridScenario`, names its scene class, its grid and its plant check, and writes
only :meth:`~slipkit.closedloop.scenarios.ClosedLoopScenario.run_trial` (the plant, the
sensor frame from its state, the controller).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar

from omegaconf import DictConfig

from slipkit._options import Rule
from slipkit.closedloop.plant import check_grid
from slipkit.closedloop.run import speed_grid
from slipkit.closedloop.scenarios import plant_params
from slipkit.errors import SlipkitError
from slipkit.sim.core import Scene


class GridScenario(ABC):
    """A scenario on one scene class whose conditions are a log-spaced grid.

    Attributes (class level)
    ------------------------
    condition_label : str
        What a condition is, with its unit (the report's column).
    family : str
        The family as the messages name it (``TacTip``).
    scene_class : type
        The scene model the scenario runs (``scene.model``'s class).
    scene_title : str
        That scene in a message (``a TacTip gravity-drop scene``).
    grid_key : str
        The scenario file's ``{lo, hi, n}`` grid (``speeds``).
    grid_rule : Rule
        The range of ``lo`` and ``hi``.
    """

    condition_label: ClassVar[str]
    family: ClassVar[str]
    scene_class: ClassVar[type]
    scene_title: ClassVar[str]
    grid_key: ClassVar[str]
    grid_rule: ClassVar[Rule]

    @abstractmethod
    def check_plant(self, plant: Mapping[str, Any]) -> None:
        """Refuse plant parameters outside their declared ranges (the family's rules)."""

    def check(self, scen: DictConfig, scene: Scene) -> None:
        """Refuse bad plant parameters and a scene of another class."""
        self.check_plant(plant_params(scen))
        if not isinstance(scene.model, self.scene_class):
            raise SlipkitError(
                f"closedloop.scene: the {self.family} closed loop needs "
                f"{self.scene_title}; got {type(scene.model).__name__}"
            )

    def conditions(self, scen: DictConfig) -> list[float]:
        """``<grid_key>.n`` log-spaced values from ``<grid_key>.lo`` to ``.hi``."""
        key = self.grid_key
        return speed_grid(
            *check_grid(dict(scen[key]), f"closedloop.{key}", self.grid_rule)
        )
