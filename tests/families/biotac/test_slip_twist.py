"""Analytic linear-vs-rotational slip classifier (slipkit.families.biotac.slip_twist) on BioTac windows."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from slipkit import config_dir
from slipkit.errors import SlipkitError
from slipkit.families.biotac.slip_twist import SlipTwistClassifier
from slipkit.sim.commands import build_scene
from slipkit.train.tasks.slip_type import WindowClassification, WindowSet


@lru_cache(maxsize=2)
def windows(seed: int) -> WindowSet:
    """50-frame windows ending 0-0.3 s after onset on 8 trials of the hard lift scene."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["scene=biotac_lift_slip_hard"])
    GlobalHydra.instance().clear()
    ds = build_scene(cfg.scene).simulate(8, seed=seed)
    task = WindowClassification(window=50, hop=3, window_end_s=[0.0, 0.3])
    return task.windows(ds, 50, "raw", span=[0.0, 0.3])


def test_twist_share_separates_linear_from_rotational_on_unseen_trials() -> None:
    """Threshold fitted on one set of simulated trials classifies another set well above chance."""
    train, test = windows(0), windows(1)
    clf = SlipTwistClassifier().fit(train.X, train.y)
    acc = float(np.mean(clf.predict(test.X) == test.y.astype(str)))
    assert ["linear", "rotational"] == clf.classes_.tolist()
    assert True == (acc > 0.75)  # noqa: E712  (chance: about 0.5)


def test_twist_share_is_zero_for_a_drag_and_one_for_a_balanced_twist() -> None:
    """One-sign change gives R = 0; equal and opposite changes give R = 1; no change gives 0."""
    start = np.zeros((4, 3))
    drag = np.vstack([start, start + np.array([1.0, 2.0, 3.0])])
    twist = np.vstack([start, start + np.array([1.0, -1.0, 0.0])])
    still = np.vstack([start, start])
    X = np.stack([drag, twist, still]).reshape(3, -1)
    r = SlipTwistClassifier(n_channels=3).twist_share(X)
    assert [0.0, 1.0, 0.0] == r.tolist()


def test_bad_width_and_labels_are_named() -> None:
    """A row that is no multiple of n_channels, or labels without the rotational class, raise."""
    with pytest.raises(SlipkitError, match="n_channels=19"):
        SlipTwistClassifier().twist_share(np.zeros((2, 20)))
    with pytest.raises(SlipkitError, match="rotational_class='rotational'"):
        SlipTwistClassifier(n_channels=1).fit(np.zeros((2, 2)), ["a", "b"])
