"""The closed-loop scenario registry: a family registers by decorator and is found by name."""

from __future__ import annotations

import pytest

from slipkit.closedloop.scenarios import (
    SCENARIOS,
    ClosedLoopScenario,
    get_scenario,
    register_scenario,
)
from slipkit.errors import SlipkitError
from slipkit.families.tactip.scenario import TacTipScenario


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
        if "unit_test_family" in SCENARIOS:
            SCENARIOS.unregister("unit_test_family")


@pytest.mark.parametrize(
    ("family", "message"),
    [("no_such_family", "no registered closed-loop scenario"), ("../x", "identifier")],
)
def test_unknown_or_bad_family_is_refused(family: str, message: str) -> None:
    """A family with no module, or a name that is no identifier, is a SlipkitError naming it."""
    with pytest.raises(SlipkitError, match=message):
        get_scenario(family)


def test_demo_block_keeps_its_detectors_and_sizes() -> None:
    """demo=true keeps the demo: block's detectors, trials and delays; an unknown detector is refused."""
    from omegaconf import OmegaConf

    from slipkit.closedloop.commands import apply_demo

    scen = OmegaConf.create(
        {
            "trials_per_speed": 4,
            "train_trials": 16,
            "detectors": {"a": {"run": "r", "debounce_k": 1}, "b": {"run": "s"}},
            "oracle_delays_ms": [10, 25],
            "demo": {"trials_per_speed": 1, "detectors": ["b"], "oracle_delays_ms": []},
        }
    )
    apply_demo(scen, "x")
    bad = OmegaConf.create({"detectors": {"a": {}}, "demo": {"detectors": ["zz"]}})
    with pytest.raises(SlipkitError, match=r"demo.detectors: \['zz'\]"):
        apply_demo(bad, "x")
    assert (1, 16, ["b"], []) == (
        scen.trials_per_speed,
        scen.train_trials,
        list(scen.detectors),
        list(scen.oracle_delays_ms),
    )


def test_every_family_scenario_shares_the_grid_skeleton() -> None:
    """Each family's scenario checks its scene and grid through GridScenario: one message
    shape for a scene of another class, one for a grid out of range."""
    from omegaconf import OmegaConf

    from slipkit.closedloop.scenarios import SCENARIOS
    from slipkit.closedloop.skeleton import GridScenario
    from slipkit.families import load_plugins

    load_plugins("scenarios")
    assert {"tactip", "biotac", "fsr", "sliptack", "davis"} <= set(SCENARIOS)
    for name in ("tactip", "biotac", "fsr", "sliptack", "davis"):
        scenario = get_scenario(name)
        assert isinstance(scenario, GridScenario), name
    davis = get_scenario("davis")
    bad = OmegaConf.create({"lift_s": {"lo": 0.3, "hi": 0.03, "n": 3}})
    with pytest.raises(SlipkitError, match=r"closedloop\.lift_s\.lo=0\.3: expected <="):
        davis.conditions(bad)
    with pytest.raises(SlipkitError, match=r"closedloop\.lift_s\.hi=.*\(0, 10\] s"):
        davis.conditions(OmegaConf.create({"lift_s": {"lo": 0.03, "hi": 60, "n": 3}}))
    assert [0.03, 0.0949, 0.3] == davis.conditions(
        OmegaConf.create({"lift_s": {"lo": 0.03, "hi": 0.3, "n": 3}})
    )
