"""The stages find the DAVIS family's parts through ``slipkit.families.PLUGIN_MODULES``:
its effects, closed-loop scenario, exporters, deployer, comparison adapter and the
analytic estimators learned-model tasks refuse; its rules train in the detector slot."""

from __future__ import annotations

from slipkit.families import PLUGIN_MODULES, detector_module, load_plugins


def test_davis_folder_registers_its_parts() -> None:
    from slipkit.closedloop.scenarios import SCENARIOS, get_scenario
    from slipkit.compare.adapters import _ADAPTERS
    from slipkit.export.deploy import _DEPLOYERS
    from slipkit.export.registry import exporter_for
    from slipkit.sim.core import EFFECTS
    from slipkit.train.task import analytic_estimators

    for kind in PLUGIN_MODULES:
        load_plugins(kind)
    from slipkit.families.davis.classifier import EventFrameClassifier
    from slipkit.families.davis.export.classifier import EventFrameScores
    from slipkit.families.davis.export.onset import DavisOnsetScores
    from slipkit.families.davis.export.polarity import DavisAreaRule
    from slipkit.families.davis.onset import DavisOnset
    from slipkit.families.davis.polarity import DavisPolarity
    from slipkit.families.davis.task import DavisRelease

    assert {"contact_events", "vibration_incidents", "background_events"} <= set(
        EFFECTS
    )
    assert "davis" in SCENARIOS
    assert get_scenario("davis") is not None
    for cls in (
        DavisAreaRule,
        DavisOnsetScores,
        EventFrameScores,
        EventFrameClassifier,
    ):
        assert exporter_for(cls) is not None, cls
    assert _DEPLOYERS.for_class(DavisRelease) is not None
    assert _ADAPTERS.for_class(DavisRelease) is not None
    refused = analytic_estimators()
    assert issubclass(DavisOnset, refused)
    assert issubclass(DavisPolarity, refused)
    assert not issubclass(EventFrameClassifier, refused)


def test_davis_rules_train_in_the_detector_slot_and_the_classifier_does_not() -> None:
    from slipkit.compare.commands import _is_analytic

    davis = "slipkit.families.davis."
    assert detector_module(davis + "polarity")
    assert detector_module(davis + "onset")
    assert not detector_module(davis + "classifier")
    assert not detector_module(davis + "export.polarity")
    assert _is_analytic("onset", {"_target_": davis + "onset.DavisOnset"}, [])
    node = {"_target_": davis + "classifier.EventFrameClassifier"}
    assert not _is_analytic("event_logreg", node, [])
