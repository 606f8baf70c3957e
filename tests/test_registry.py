"""The one registry type: duplicates refused, signatures checked, MRO lookup, and every
plug-in table of slipkit built on it."""

from __future__ import annotations

from typing import Any

import pytest

from slipkit._registry import Registry


def _two(a: Any, b: Any) -> None:
    return None


def _one(a: Any) -> None:
    return None


def test_a_second_entry_under_a_key_is_refused_with_the_registrys_error() -> None:
    """Registering another object under a taken key raises the registry's own error type."""
    reg: Registry[str, Any] = Registry("widget", error=KeyError, n_args=2)
    reg.register("a", _two)
    with pytest.raises(KeyError, match="widget is already registered for 'a'"):
        reg.register("a", lambda x, y: None)
    assert _two is reg["a"]


def test_the_same_object_twice_is_one_entry_and_overwrite_replaces() -> None:
    """Re-registering the identical object is a no-op; overwrite=True replaces the entry."""
    reg: Registry[str, Any] = Registry("widget", n_args=2)
    reg.register("a", _two)
    reg.register("a", _two)
    other = lambda x, y: None  # noqa: E731
    reg.register("a", other, overwrite=True)
    assert (1, other) == (len(reg), reg["a"])


def test_a_wrong_signature_or_key_type_is_refused_where_it_is_registered() -> None:
    """An entry that cannot take the kind's positional arguments, or a key of the wrong type,
    fails at registration, naming the key."""
    reg: Registry[Any, Any] = Registry("exporter", n_args=2, key_type=type)
    with pytest.raises(TypeError, match=r"must accept 2 positional"):
        reg.register(int, _one)
    with pytest.raises(TypeError, match="needs a class as its key"):
        reg.register("int", _two)
    with pytest.raises(TypeError, match="not callable"):
        reg.register(int, 3)
    assert 0 == len(reg)


def test_for_class_walks_the_mro() -> None:
    """A subclass without its own entry gets its nearest base's; an unrelated class None."""

    class Base:
        pass

    class Child(Base):
        pass

    reg: Registry[type, Any] = Registry("deployer", key_type=type)
    reg.register(Base, "base entry")
    assert ("base entry", None) == (reg.for_class(Child), reg.for_class(int))


def test_every_plug_in_table_is_a_registry_that_refuses_duplicates() -> None:
    """Exporters, deployers, comparison adapters, effects, scenarios and runtime ops share
    the one registry type; a different adapter for a registered task class, or a
    different window rule for a registered rule class, is refused."""
    from slipkit.closedloop.scenarios import SCENARIOS
    from slipkit.compare import adapters
    from slipkit.errors import SlipkitError
    from slipkit.export import deploy, registry
    from slipkit.runtime.preprocessing import OPS
    from slipkit.sim.core import EFFECTS
    from slipkit.train.tasks.detection import StreamDetection

    tables = [
        registry._EXPORTERS,
        deploy._DEPLOYERS,
        deploy._WINDOW_RULES,
        adapters._ADAPTERS,
        EFFECTS,
        SCENARIOS,
        OPS,
    ]
    assert [True] * 7 == [isinstance(t, Registry) for t in tables]
    with pytest.raises(SlipkitError, match="already registered"):
        adapters.register_adapter(StreamDetection, lambda view: None)
    from slipkit.families.biotac.slip_twist import SlipTwistClassifier

    with pytest.raises(SlipkitError, match="already registered"):
        deploy.register_window_rule(SlipTwistClassifier, lambda model: ["1"])


def test_runtime_steps_come_from_the_detector_class_not_the_deployer():
    """The FSR detector's press_sign step and the pressure detector's fixed baseline are
    registered beside their graphs; a class without an entry gets no step; a second
    registration is refused."""
    import slipkit.export  # noqa: F401  (registers every family's exporters)
    from slipkit.export.registry import (
        _RUNTIME_STEPS,
        ExportError,
        RuntimeSteps,
        StreamContext,
        register_runtime_steps,
        runtime_steps,
    )
    from slipkit.families.biotac.detectors import PressureVibration
    from slipkit.families.fsr.onset import FSROnset, FSROnsetLogistic
    from slipkit.families.fsr.touch_slip import FSRTouchSlip

    assert {FSRTouchSlip, PressureVibration, FSROnset} <= set(_RUNTIME_STEPS)
    assert _RUNTIME_STEPS.for_class(FSROnsetLogistic) is _RUNTIME_STEPS[FSROnset]
    ctx = StreamContext("s", ["a"], [], [], lambda ids: [])
    assert RuntimeSteps() == runtime_steps(object(), ctx)
    with pytest.raises(ExportError):
        register_runtime_steps(FSROnset, lambda det, ctx: RuntimeSteps())
