"""Every file in configs/ composes, and every `_target_` in it instantiates."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate

from slipkit import config_dir

CONFIGS = config_dir()
#: config group -> the subcommand config that composes it
GROUP_PRIMARY = {
    "scene": "simulate",
    "source": "import",
    "model": "train",
    "task": "train",
    "detector": "train",
    "experiment": "train",
    "deploy": "export",
    "comparison": "compare",
    "closedloop": "closedloop",
    "search": "sweep",
}
PRIMARY = sorted(p.stem for p in CONFIGS.glob("*.yaml"))
GROUP_FILES = sorted(
    (group, p.stem) for group in GROUP_PRIMARY for p in (CONFIGS / group).glob("*.yaml")
)


def test_every_config_group_is_covered() -> None:
    """Each config folder (but Hydra's own) is composed by one of the tests below."""
    groups = {p.name for p in CONFIGS.iterdir() if p.is_dir()} - {"hydra"}
    assert groups == set(GROUP_PRIMARY)


@pytest.mark.parametrize("name", PRIMARY)
def test_subcommand_config_composes(name: str) -> None:
    """Each subcommand's config composes with its defaults."""
    with initialize_config_dir(config_dir=str(CONFIGS), version_base="1.3"):
        cfg = compose(config_name=name)
    assert cfg is not None


@pytest.mark.parametrize(("group", "option"), GROUP_FILES)
def test_group_option_instantiates(group: str, option: str) -> None:
    """Each scene model and each importer in configs/ builds with hydra.utils.instantiate."""
    with initialize_config_dir(config_dir=str(CONFIGS), version_base="1.3"):
        cfg = compose(config_name=GROUP_PRIMARY[group], overrides=[f"{group}={option}"])
    if group == "experiment":
        # An experiment is global: it picks the task and the estimator (model or detector).
        from slipkit.train.commands import estimator_node

        assert instantiate(cfg.task) is not None
        assert instantiate(estimator_node(cfg)) is not None
        assert cfg.name == option
        return
    node = cfg[group]
    target = node.model if group == "scene" else node
    obj = instantiate(target)
    assert obj is not None
    if group == "scene":
        from slipkit.sim.commands import build_scene

        scene = build_scene(node)
        assert option == scene.name


def test_wheel_ships_the_config_tree(tmp_path: Path) -> None:
    """A built wheel carries every file of configs/ as slipkit/configs/."""
    import zipfile

    from tests.wheel import build_wheel

    wheel = build_wheel(tmp_path)
    names = set(zipfile.ZipFile(wheel).namelist())
    expected = {
        f"slipkit/configs/{p.relative_to(CONFIGS).as_posix()}"
        for p in CONFIGS.rglob("*.yaml")
    }
    assert expected <= names
