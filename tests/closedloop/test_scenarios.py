"""The closed-loop scenario registry: a family registers by decorator and is found by name."""

from __future__ import annotations

import pytest

from slipkit.closedloop.scenarios import (
    SCENARIOS,
    ClosedLoopScenario,
    get_scenario,
    register_scenario,
)
from slipkit.closedloop.tactip import TacTipScenario
from slipkit.errors import SlipkitError


def test_tactip_is_registered_under_its_family_name() -> None:
    """get_scenario('tactip') returns the TacTip scenario, which satisfies the protocol."""
    scenario = get_scenario("tactip")
    assert (True, True) == (
        isinstance(scenario, TacTipScenario),
        isinstance(scenario, ClosedLoopScenario),
    )


def test_a_decorated_class_is_found_by_name() -> None:
    """@register_scenario(name) makes get_scenario(name) build that class."""

    @register_scenario("unit_test_family")
    class Dummy:
        condition_label = "x (1)"

        def check(self, scen, scene):  # type: ignore[no-untyped-def]
            del scen, scene

        def conditions(self, scen):  # type: ignore[no-untyped-def]
            return [1.0]

        def run_trial(self, scene, detector, plant, **kw):  # type: ignore[no-untyped-def]
            raise AssertionError("not run here")

    try:
        assert "Dummy" == type(get_scenario("unit_test_family")).__name__
    finally:
        SCENARIOS.pop("unit_test_family", None)


@pytest.mark.parametrize(
    ("family", "message"),
    [("no_such_family", "no registered closed-loop scenario"), ("../x", "identifier")],
)
def test_unknown_or_bad_family_is_refused(family: str, message: str) -> None:
    """A family with no module, or a name that is no identifier, is a SlipkitError naming it."""
    with pytest.raises(SlipkitError, match=message):
        get_scenario(family)
