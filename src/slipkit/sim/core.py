"""The scene simulator's machinery: state, effect registry, scene, and the trial loop.

A *scene model* (one per scene: ``sliptack_pull``, ``tactip_gravity_drop``...) draws a
trial's parameters and builds the physical backbone of the trial (phases, contact,
kinematics, the sensor's noiseless response). Everything else is an *effect*: a small
pure function ``effect(state, rng, **params) -> state`` with one physical meaning,
registered by name. A scene config lists the effects it needs, in order, with their
parameters; the simulator evaluates exactly those and nothing else.

Determinism: trial ``i`` of a run with seed ``s`` draws from
``numpy.random.default_rng([s, i])``, so a trial does not depend on how many trials
were asked for, and the same seed gives byte-identical dataset files.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import pandas as pd

from slipkit.data.dataset import Dataset, LabelSpec, StreamSpec, Trial
from slipkit.errors import SlipkitError


class SimulationError(SlipkitError, ValueError):
    """A scene config asks for something the simulator cannot do (names the key)."""


@dataclass(frozen=True)
class SceneState:
    """What effects read and transform.

    Attributes
    ----------
    time : dict of str to ndarray
        Sample times (s) per stream, e.g. ``time["pac"]`` at 2.2 kHz.
    signals : dict of str to ndarray
        Named arrays, first axis aligned with the matching ``time`` entry
        (``signals["pac"]``) or free-form for latent quantities (``signals["contact_area"]``).
    truth : dict
        Ground truth and trial parameters (``slip_onset_s``, ``speed_mm_s``...).
    """

    time: Mapping[str, np.ndarray]
    signals: Mapping[str, np.ndarray]
    truth: Mapping[str, Any] = field(default_factory=dict)

    def with_signal(self, name: str, value: np.ndarray) -> SceneState:
        """A new state with ``signals[name]`` replaced (effects stay pure)."""
        return dataclasses.replace(self, signals={**self.signals, name: value})

    def with_time(self, name: str, value: np.ndarray) -> SceneState:
        """A new state with ``time[name]`` replaced."""
        return dataclasses.replace(self, time={**self.time, name: value})

    def with_truth(self, **values: Any) -> SceneState:
        """A new state with ground-truth entries added or replaced."""
        return dataclasses.replace(self, truth={**self.truth, **values})

    def truth_value(self, key: str, effect: str) -> Any:
        """``truth[key]``, or a :class:`SimulationError` naming the effect that needs it."""
        if key not in self.truth:
            raise SimulationError(
                f"effect {effect!r} needs ground truth {key!r}, which this scene does not "
                f"provide; truth: {sorted(self.truth)}"
            )
        return self.truth[key]

    def signal(self, name: str, effect: str) -> np.ndarray:
        """``signals[name]``, or a :class:`SimulationError` naming the effect that needs it."""
        if name not in self.signals:
            raise SimulationError(
                f"effect {effect!r} acts on signal {name!r}, which this scene does not produce; "
                f"signals: {sorted(self.signals)}"
            )
        return self.signals[name]


Effect = Callable[..., SceneState]
EFFECTS: dict[str, Effect] = {}


def register_effect(name: str) -> Callable[[Effect], Effect]:
    """Decorator: register an effect under ``name`` (refuses duplicates)."""

    def deco(fn: Effect) -> Effect:
        if name in EFFECTS and EFFECTS[name] is not fn:
            raise ValueError(
                f"effect {name!r} is already registered by {EFFECTS[name].__module__}"
            )
        EFFECTS[name] = fn
        return fn

    return deco


class SceneModel(Protocol):
    """The physical backbone of one scene (see module docstring)."""

    sensor: str
    groups: tuple[str, ...]

    def streams(self) -> dict[str, StreamSpec]:
        """Streams the rendered trials hold."""

    def labels(self) -> dict[str, LabelSpec]:
        """Trial-level labels the rendered trials carry."""

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """Draw one trial's parameters (speed, material, object...)."""

    def base(self, params: Mapping[str, Any], rng: np.random.Generator) -> SceneState:
        """Build the trial's noiseless backbone from its parameters."""

    def render(
        self, state: SceneState
    ) -> tuple[dict[str, pd.DataFrame], dict[str, Any], dict[str, Any]]:
        """Turn the final state into (streams, labels, meta) of a :class:`Trial`."""


def effect_name(key: str) -> str:
    """The registered effect behind a scene's effect key (``white_noise@pac`` -> ``white_noise``)."""
    return key.split("@", 1)[0]


def _load_effect_modules() -> None:
    # Importing registers the effects; kept here so `EFFECTS` is complete before a run.
    from slipkit.sim import effects  # noqa: F401


@dataclass
class Scene:
    """A scene: a model plus the ordered effects it names.

    Parameters
    ----------
    name : str
        Scene name (``sliptack_pull``); becomes the dataset name.
    model : SceneModel
        Built by ``hydra.utils.instantiate`` from ``configs/scene/<name>.yaml``.
    effects : mapping of str to mapping
        Effect name -> keyword parameters, evaluated in this order. ``null`` parameters
        mean "no parameters". An effect absent here is never called. To apply one
        effect twice (e.g. noise on two streams), suffix the key: ``white_noise@pac``.
    """

    name: str
    model: SceneModel
    effects: Mapping[str, Mapping[str, Any] | None] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _load_effect_modules()
        unknown = [e for e in self.effects if effect_name(e) not in EFFECTS]
        if unknown:
            raise SimulationError(
                f"scene {self.name!r}: unknown effects {unknown} (scene.effects); known: {sorted(EFFECTS)}"
            )

    def run_trial(self, index: int, seed: int) -> Trial:
        """Simulate trial ``index`` of a run seeded with ``seed``."""
        rng = np.random.default_rng([int(seed), int(index)])
        params = self.model.sample(rng)
        state = self.model.base(params, rng)
        for name, kwargs in self.effects.items():
            state = EFFECTS[effect_name(name)](state, rng, **dict(kwargs or {}))
        streams, labels, meta = self.model.render(state)
        return Trial(
            trial_id=f"{self.name}-{index:05d}",
            streams=streams,
            labels=labels,
            meta=meta,
        )

    def simulate(
        self,
        n_trials: int,
        seed: int = 0,
        *,
        progress: bool = False,
        config: Any = None,
    ) -> Dataset:
        """Simulate ``n_trials`` trials into a :class:`Dataset` (provenance: scene, seed, config)."""
        if n_trials < 1:
            raise SimulationError(f"n_trials must be >= 1; got {n_trials}")
        indices: Iterable[int] = range(n_trials)
        if progress:
            from tqdm import tqdm

            indices = tqdm(
                indices, desc=f"simulate {self.name}", unit="trial", leave=False
            )
        trials = [self.run_trial(i, seed) for i in indices]
        provenance: dict[str, Any] = {
            "scene": self.name,
            "seed": int(seed),
            "n_trials": int(n_trials),
            "effects": list(self.effects),
        }
        if config is not None:
            provenance["config"] = config
        return Dataset.from_trials(
            trials,
            sensor=self.model.sensor,
            streams=self.model.streams(),
            labels=self.model.labels(),
            groups=self.model.groups,
            provenance=provenance,
            name=self.name,
        )


def phase_times(phases: Mapping[str, float]) -> dict[str, tuple[float, float]]:
    """Start and end (s) of consecutive phases given their durations (s), in order.

    >>> phase_times({"press": 0.5, "hold": 1.0})
    {'press': (0.0, 0.5), 'hold': (0.5, 1.5)}
    """
    out: dict[str, tuple[float, float]] = {}
    start = 0.0
    for name, dur in phases.items():
        if dur < 0:
            raise SimulationError(f"phase {name!r} has negative duration {dur} s")
        out[name] = (start, start + float(dur))
        start += float(dur)
    return out


def sample_times(duration_s: float, rate_hz: float) -> np.ndarray:
    """Regular sample times ``k / rate`` (s) covering ``[0, duration)``."""
    if rate_hz <= 0:
        raise SimulationError(f"rate_hz must be > 0; got {rate_hz}")
    return np.arange(round(duration_s * rate_hz), dtype=np.float64) / float(rate_hz)
