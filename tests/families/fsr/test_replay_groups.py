"""The FSR wiring groups a stream-detection bundle's replay through the ``fsr_polarity``
effect's declaration; the generic deployer names no family."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from slipkit.sim.core import register_effect, replay_groups


def test_the_fsr_polarity_effect_declares_the_wiring_a_replay_group() -> None:
    assert "fsr_polarity.polarity" in replay_groups()


def test_a_replay_group_must_be_a_choice_draw() -> None:
    with pytest.raises(ValueError, match="replay_groups \\['a'\\]"):
        register_effect("_no_such_effect", draws={"a": "uniform"}, replay_groups=("a",))
    with pytest.raises(ValueError, match="replay_groups \\['b'\\]"):
        register_effect("_no_such_effect", replay_groups=("b",))


def test_the_stream_detection_deployer_names_no_family() -> None:
    from slipkit.families import FAMILIES

    deploy = importlib.import_module("slipkit.export.deploy")
    text = Path(deploy.__file__).with_name("deploy_detection.py").read_text()  # type: ignore[arg-type]
    named = [f for f in FAMILIES if f in text.lower()]
    assert [] == named
