"""Shared fixtures of the export tests: a few simulated TacTip gravity-drop trials."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from numpy.typing import NDArray

from slipkit import config_dir
from slipkit.data import split_by_trial
from slipkit.data.dataset import Dataset
from slipkit.families.tactip.features import dataset_features
from slipkit.sim.commands import build_scene


class DropData(NamedTuple):
    """Training features and held-out features plus the raw pin-frame pairs they come from."""

    X_train: NDArray[np.float64]
    y_train: NDArray[np.str_]
    X_test: NDArray[np.float64]
    y_test: NDArray[np.str_]
    pins_test: NDArray[np.float32]
    pins_test64: NDArray[np.float64]


def pin_pairs(dataset: Dataset) -> NDArray[np.float64]:
    """``(n_velocity_frames, 2, 2N)`` previous/current pin frames of every trial (mm)."""
    pairs = []
    for trial in dataset:
        frames = trial.streams["pins"].drop(columns="t").to_numpy(dtype=np.float64)
        pairs.append(np.stack([frames[:-1], frames[1:]], axis=1))
    return np.concatenate(pairs)


@pytest.fixture(scope="session")
def drop_data() -> DropData:
    """6 simulated gravity-drop trials (seed 0): 3 to train, 3 held out."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=tactip_gravity_drop"])
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    ds = build_scene(cfg.scene).simulate(6, seed=0)
    train, _, test = split_by_trial(ds, test_size=0.5, seed=0).apply(ds)
    tr, te = dataset_features(train), dataset_features(test)
    pins = pin_pairs(test)
    return DropData(tr.X, tr.y, te.X, te.y, pins.astype(np.float32), pins)
