"""``slipkit simulate scene=<name> n_trials=<n> seed=<s> out=<dir>``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hydra.errors import InstantiationException
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from slipkit._files import check_out_path
from slipkit.data.io import save_dataset
from slipkit.data.summary import summarize
from slipkit.errors import SlipkitError
from slipkit.sim.core import Scene

#: numbers one simulated trial may hold (float64: 400 MB); the shipped scenes hold at
#: most a few hundred thousand
MAX_TRIAL_VALUES = 50_000_000


#: the unit before a final ``_s`` that makes an option a rate, not a duration
#: (``speed_mm_s``, ``gain_counts_per_N_s``)
_PER_SECOND = {"mm", "m", "N", "rad", "deg", "px", "V", "per"}


def _trial_seconds(model_cfg: Any) -> float:
    """An upper estimate of one trial's length, s: the sum of the model's ``*_s`` options
    (a ``[lo, hi]`` range counts ``hi``). Phases, onsets and delays alike are summed: an
    over-estimate only makes the size check (:func:`check_trial_size`) stricter."""
    plain = (
        OmegaConf.to_container(model_cfg, resolve=True) if model_cfg is not None else {}
    )
    total = 0.0
    for key, value in (plain if isinstance(plain, dict) else {}).items():
        items = value if isinstance(value, list) else [value]
        numbers = [
            float(v)
            for v in items
            if isinstance(v, int | float) and not isinstance(v, bool)
        ]
        parts = str(key).split("_")
        duration = parts[-1] == "s" and (len(parts) < 2 or parts[-2] not in _PER_SECOND)
        if duration and numbers and len(numbers) == len(items):
            total += max(0.0, max(numbers))
    return total


def check_trial_size(scene: Scene, model_cfg: Any) -> None:
    """Refuse a scene whose trial would hold more than :data:`MAX_TRIAL_VALUES` numbers.

    Each sampled stream holds ``rate x length x channels`` numbers; a typo such as
    ``duration_s=1e9`` would otherwise fill the memory before any message.
    """
    seconds = _trial_seconds(model_cfg)
    for name, spec in scene.model.streams().items():
        if spec.rate_hz is None:
            continue
        values = float(spec.rate_hz) * seconds * max(1, len(spec.channels))
        if values > MAX_TRIAL_VALUES:
            raise SlipkitError(
                f"scene {scene.name!r}: stream {name!r} would hold about {values:.2g} numbers "
                f"per trial ({spec.rate_hz:g} Hz x {seconds:g} s x {len(spec.channels)} "
                f"channels; at most {MAX_TRIAL_VALUES:.0e}); lower scene.model's rate or "
                "durations (*_s)"
            )


def build_scene(scene_cfg: DictConfig) -> Scene:
    """A :class:`Scene` from a ``configs/scene/*.yaml`` node (model via ``instantiate``).

    A model that refuses its parameters raises a :class:`SlipkitError` naming the key;
    Hydra wraps it in ``InstantiationException``, which is unwrapped here so the CLI
    prints the message instead of a traceback.
    """
    node = scene_cfg.get("effects")
    effects: Any = {}
    if node is not None and len(node):
        effects = OmegaConf.to_container(node, resolve=True)
    try:
        model = instantiate(scene_cfg.model)
    except InstantiationException as exc:
        if isinstance(exc.__cause__, SlipkitError):
            raise exc.__cause__ from None
        raise
    order = scene_cfg.get("order")
    if order is not None:
        order = [str(k) for k in order]
    scene = Scene(name=str(scene_cfg.name), model=model, effects=effects, order=order)
    check_trial_size(scene, scene_cfg.get("model"))
    return scene


def simulate_main(cfg: DictConfig) -> Path:
    """Simulate ``cfg.n_trials`` trials of ``cfg.scene`` and write the dataset to ``cfg.out``."""
    out = check_out_path(str(cfg.out), kind="dataset", overwrite=bool(cfg.overwrite))
    scene = build_scene(cfg.scene)
    config = OmegaConf.to_container(cfg.scene, resolve=True)
    dataset = scene.simulate(
        int(cfg.n_trials), int(cfg.seed), progress=bool(cfg.progress), config=config
    )
    out = save_dataset(dataset, out, overwrite=bool(cfg.overwrite))
    if cfg.summary:
        print(summarize(dataset))
    print(out)
    return out
