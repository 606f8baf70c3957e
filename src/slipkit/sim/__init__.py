"""Scene simulator: sensor backbones plus only the effects a scene names.

See ``docs/simulation.md`` for every effect's equation and source.
"""

from slipkit.sim import effects as _effects  # noqa: F401  (registers every effect)
from slipkit.sim.core import (
    EFFECTS,
    Scene,
    SceneModel,
    SceneState,
    SimulationError,
    phase_times,
    register_effect,
    sample_times,
)

__all__ = [
    "EFFECTS",
    "Scene",
    "SceneModel",
    "SceneState",
    "SimulationError",
    "phase_times",
    "register_effect",
    "sample_times",
]
