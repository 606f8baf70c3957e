"""The dataset a run trains on: a dataset folder, a raw recording, or a simulated scene."""

from __future__ import annotations

from pathlib import Path

from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from slipkit.data.dataset import Dataset
from slipkit.data.io import load_dataset
from slipkit.errors import SlipkitError
from slipkit.sim.commands import build_scene


def training_dataset(cfg: DictConfig) -> Dataset:
    """The dataset named by ``cfg.dataset`` (see ``configs/train.yaml``).

    In order of precedence: ``dataset.path`` (a slipkit dataset folder);
    ``dataset.raw`` read by the importer ``cfg.source`` (a public recording in its
    own layout, converted in memory); else ``dataset.n_trials`` trials of the scene
    ``cfg.scene`` simulated with ``dataset.seed``.
    """
    node = cfg.dataset
    if node.get("path"):
        return load_dataset(Path(str(node.path)))
    if node.get("raw"):
        if cfg.get("source") is None:
            raise SlipkitError(
                "dataset.raw is set but no importer is chosen (source=<name>)"
            )
        raw = Path(str(node.raw))
        if not raw.exists():
            raise SlipkitError(
                f"{raw}: recording not found (dataset.raw=...; set SLIPKIT_DATA to the "
                "folder holding the public recordings, see ../shared/data/README.md)"
            )
        dataset: Dataset = instantiate(cfg.source)(raw)
        return dataset
    if cfg.get("scene") is None:
        raise SlipkitError("no dataset: set dataset.path=<folder> or scene=<name>")
    scene = build_scene(cfg.scene)
    config = OmegaConf.to_container(cfg.scene, resolve=True)
    return scene.simulate(
        int(node.n_trials), int(node.seed), progress=False, config=config
    )
