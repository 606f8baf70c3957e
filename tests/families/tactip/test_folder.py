"""The stages find the TacTip family's parts through ``slipkit.families.PLUGIN_MODULES``
(never by a static import): effects, closed-loop scenario, exporters, deployer,
comparison adapters and the trial-event measure of its stream detectors."""

from __future__ import annotations

from slipkit.families import FAMILIES, PLUGIN_MODULES, detector_module, load_plugins


def test_tactip_folder_registers_its_parts_when_loaded() -> None:
    from slipkit.closedloop.scenarios import SCENARIOS, get_scenario
    from slipkit.compare.adapters import _ADAPTERS, _TRIAL_EVENTS
    from slipkit.export.deploy import _DEPLOYERS
    from slipkit.export.registry import exporter_for
    from slipkit.sim.core import EFFECTS

    for kind in PLUGIN_MODULES:
        load_plugins(kind)
    from slipkit.families.tactip.detector import PinMotionDetector
    from slipkit.families.tactip.task import TacTipFrames
    from slipkit.families.tactip.task_table import TacTipTable1
    from slipkit.models.svm import TacTipSVM

    assert {
        "skin_stretch",
        "snap_back",
        "pin_jitter",
        "missing_pins",
        "missing_pin_frames",
        "mindlin_creep",
    } <= set(EFFECTS)
    assert "tactip" in SCENARIOS
    assert get_scenario("tactip") is not None
    assert exporter_for(TacTipSVM()) is not None
    assert exporter_for(PinMotionDetector()) is not None
    assert _DEPLOYERS.for_class(TacTipFrames) is not None
    assert _ADAPTERS.for_class(TacTipTable1) is _ADAPTERS.for_class(TacTipFrames)
    assert _ADAPTERS.for_class(TacTipFrames) is not None
    assert "tactip" in _TRIAL_EVENTS


def test_tactip_detector_trains_in_the_detector_slot() -> None:
    """The pin-motion detector's module is a detector module (analytic kind); the
    exporters beside it are not."""
    assert "slipkit.families.tactip.detector" in FAMILIES["tactip"].detectors
    assert detector_module("slipkit.families.tactip.detector")
    assert detector_module("slipkit.baselines.tactip")  # the old path of saved runs
    assert not detector_module("slipkit.families.tactip.export.detector")
