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

Randomised effect parameters: an effect registers which of its parameters may be drawn
per trial and how (``register_effect(name, draws={"sigma": "log"})``: ``uniform``,
``log`` for log-uniform, ``choice`` for one of a list). A scene config then gives such a
parameter either as a scalar (fixed, no draw) or as ``[lo, hi]`` (a list of options for
``choice``), and :func:`draw_effect_params` draws it from the trial's generator just
before the effect runs. The drawn values join the trial's metadata as
``<effect key>.<parameter>`` columns. Parameters an effect does not declare pass through
unchanged, so effects that take ``[lo, hi]`` per event (``fsr_disturbance``) or a pair
(``quantisation.full_scale``) keep their meaning.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np
import pandas as pd

from slipkit._registry import Registry
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
EFFECTS: Registry[str, Effect] = Registry(
    "effect", error=ValueError, n_args=2, key_type=str
)
Draw = Literal["uniform", "log", "choice"]
#: effect name -> {parameter: how a ``[lo, hi]`` (or list) value is drawn per trial}
EFFECT_DRAWS: dict[str, dict[str, Draw]] = {}
#: effect name -> its drawn parameters whose value changes what a deployed bundle meets
#: (e.g. a sensor's wiring): a deployment's replay covers each value (:func:`replay_groups`)
EFFECT_REPLAY_GROUPS: dict[str, tuple[str, ...]] = {}
_DRAW_KINDS = ("uniform", "log", "choice")


def register_effect(
    name: str,
    *,
    draws: Mapping[str, Draw] | None = None,
    replay_groups: Sequence[str] = (),
) -> Callable[[Effect], Effect]:
    """Decorator: register an effect under ``name`` (refuses duplicates).

    Parameters
    ----------
    name : str
        Registry name, the key a scene config lists.
    draws : mapping of str to {"uniform", "log", "choice"}, optional
        Parameters that a scene may give as ``[lo, hi]`` (or, for ``choice``, a list of
        options) to draw them once per trial: uniform, log-uniform (``lo > 0``) or one
        option with equal probability (see :func:`draw_effect_params`).
    replay_groups : sequence of str, optional
        Drawn parameters (``choice``) whose value changes what a deployed bundle meets,
        such as a sensor's wiring: a bundle's replay holds held-out trials of each
        value drawn (:func:`replay_groups`).
    """
    spec = dict(draws or {})
    bad = {p: k for p, k in spec.items() if k not in _DRAW_KINDS}
    if bad:
        raise ValueError(
            f"effect {name!r}: unknown draw kinds {bad}; use {_DRAW_KINDS}"
        )
    groups = tuple(replay_groups)
    not_choice = [p for p in groups if spec.get(p) != "choice"]
    if not_choice:
        raise ValueError(
            f"effect {name!r}: replay_groups {not_choice} are not drawn as 'choice'"
        )

    def deco(fn: Effect) -> Effect:
        EFFECTS.register(name, fn)
        EFFECT_DRAWS[name] = spec
        if groups:
            EFFECT_REPLAY_GROUPS[name] = groups
        return fn

    return deco


def replay_groups() -> tuple[str, ...]:
    """The trials-table columns (``<effect>.<parameter>``, as :func:`draw_effect_params`
    records a drawn value) of every effect's ``replay_groups``, in registration order."""
    return tuple(
        f"{e}.{p}" for e, params in EFFECT_REPLAY_GROUPS.items() for p in params
    )


def _is_list(value: Any) -> bool:
    return isinstance(value, Sequence) and not isinstance(value, str | bytes)


def check_fixed_params(key: str, params: Mapping[str, Any] | None) -> None:
    """Refuse a fixed value of a numeric drawable parameter that is not a finite number.

    Checked once per scene (before the first trial), so ``sigma=abc`` is one line
    naming the field instead of numpy's error in the middle of a run.
    """
    kwargs = dict(params or {})
    for param, kind in EFFECT_DRAWS.get(effect_name(key), {}).items():
        fixed = kwargs.get(param)
        if fixed is None or kind == "choice" or _is_list(fixed):
            continue
        number = isinstance(fixed, int | float) and not isinstance(fixed, bool)
        if not (number and np.isfinite(fixed)):
            raise SimulationError(
                f"scene.effects.{key}.{param}: expected a finite number or [lo, hi]; "
                f"got {fixed!r}"
            )


def draw_effect_params(
    key: str, params: Mapping[str, Any] | None, rng: np.random.Generator
) -> tuple[dict[str, Any], dict[str, Any]]:
    """An effect's keyword arguments for one trial, with declared ranges drawn.

    For each parameter the effect declared drawable (in declaration order, so the
    draws do not depend on the order of the config's keys): a scalar stays fixed and
    consumes no random numbers; ``[lo, hi]`` with ``lo < hi`` is drawn uniformly
    (``uniform``) or log-uniformly (``log``: ``exp(U(log lo, log hi))``); ``[v, v]``
    is ``v``; for ``choice`` a list gives one of its entries, each equally likely.

    Parameters
    ----------
    key : str
        The scene's effect key (``white_noise@pac``); names the field on error.
    params : mapping or None
        The configured parameters.
    rng : numpy.random.Generator
        The trial's generator.

    Returns
    -------
    kwargs : dict
        Parameters to call the effect with.
    drawn : dict
        ``{"<key>.<parameter>": value}`` for each parameter drawn from a range.
    """
    kwargs = dict(params or {})
    drawn: dict[str, Any] = {}
    for param, kind in EFFECT_DRAWS.get(effect_name(key), {}).items():
        if param not in kwargs or not _is_list(kwargs[param]):
            continue
        where = f"scene.effects.{key}.{param}"
        options = list(kwargs[param])
        if kind == "choice":
            if not options:
                raise SimulationError(f"{where}: list at least one option")
            value = (
                options[0]
                if len(options) == 1
                else options[int(rng.integers(len(options)))]
            )
        else:
            try:
                lo, hi = (float(v) for v in options)
            except (TypeError, ValueError):
                raise SimulationError(
                    f"{where}: expected a number or [lo, hi]; got {options!r}"
                ) from None
            if not (np.isfinite(lo) and np.isfinite(hi)) or hi < lo:
                raise SimulationError(
                    f"{where}: expected finite lo <= hi; got {options!r}"
                )
            if kind == "log" and lo <= 0:
                raise SimulationError(
                    f"{where}: a log-uniform range needs lo > 0; got {options!r}"
                )
            if lo == hi:
                value = lo
            elif kind == "log":
                value = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
            else:
                value = float(rng.uniform(lo, hi))
        kwargs[param] = value
        drawn[f"{key}.{param}"] = value
    return kwargs, drawn


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
        A parameter the effect declares drawable may be ``[lo, hi]``: drawn per trial
        (:func:`draw_effect_params`) and recorded in the trial's metadata.
    order : sequence of str, optional
        Evaluation order: every key of ``effects`` once (keys naming no listed effect
        are skipped, so removing an effect from a variant needs no new order); default:
        their mapping order. A variant that composes a base scene (Hydra defaults) can
        only append effects to the base mapping, so it states the order here.
    """

    name: str
    model: SceneModel
    effects: Mapping[str, Mapping[str, Any] | None] = field(default_factory=dict)
    order: Sequence[str] | None = None

    def __post_init__(self) -> None:
        _load_effect_modules()
        unknown = [e for e in self.effects if effect_name(e) not in EFFECTS]
        if unknown:
            raise SimulationError(
                f"scene {self.name!r}: unknown effects {unknown} (scene.effects); known: {sorted(EFFECTS)}"
            )
        for key, params in self.effects.items():
            check_fixed_params(key, params)
        if self.order is not None:
            order = [str(k) for k in self.order]
            missing = sorted(set(self.effects) - set(order))
            repeated = sorted({k for k in order if order.count(k) > 1})
            if missing or repeated:
                raise SimulationError(
                    f"scene {self.name!r}: scene.order must list each key of scene.effects "
                    f"once; missing {missing}, repeated {repeated}"
                )
            # Keys without an effect are skipped, so `~scene.effects.x` works on a variant.
            self.order = tuple(k for k in order if k in self.effects)

    def effect_keys(self) -> tuple[str, ...]:
        """The effect keys in evaluation order."""
        return tuple(self.order) if self.order is not None else tuple(self.effects)

    def run_trial(self, index: int, seed: int) -> Trial:
        """Simulate trial ``index`` of a run seeded with ``seed``.

        Per-trial draws of effect parameters are added to the trial's metadata under
        ``<effect key>.<parameter>`` (and to ``truth["drawn"]`` for the effects).
        """
        rng = np.random.default_rng([int(seed), int(index)])
        params = self.model.sample(rng)
        state = self.model.base(params, rng)
        drawn: dict[str, Any] = {}
        for name in self.effect_keys():
            kwargs, new = draw_effect_params(name, self.effects[name], rng)
            if new:
                drawn.update(new)
                state = state.with_truth(drawn=dict(drawn))
            state = EFFECTS[effect_name(name)](state, rng, **kwargs)
        streams, labels, meta = self.model.render(state)
        return Trial(
            trial_id=f"{self.name}-{index:05d}",
            streams=streams,
            labels=labels,
            meta={**meta, **drawn},
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
        for stream in self.model.streams():
            if all(len(t.streams.get(stream, ())) == 0 for t in trials):
                raise SimulationError(
                    f"scene {self.name!r}: stream {stream!r} has no samples in any of the "
                    f"{n_trials} trials (is scene.model's rate or duration too small?)"
                )
        provenance: dict[str, Any] = {
            "scene": self.name,
            "seed": int(seed),
            "n_trials": int(n_trials),
            "effects": list(self.effect_keys()),
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
