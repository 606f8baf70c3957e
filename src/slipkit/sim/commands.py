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
    return Scene(name=str(scene_cfg.name), model=model, effects=effects, order=order)


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
