"""The demo's closed loop runs the verdict bundle's own operating point (its debounce)."""

from __future__ import annotations

from hydra import compose, initialize_config_dir

from slipkit import config_dir
from slipkit.demo import _closedloop_detector

_DAVIS = ["closedloop=davis", "seeds=[0]"]
_SHOWN = {"onset": "onset_k2"}


def _pick(verdict: str, k: int | None) -> tuple[str | None, list[str]]:
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        pick, overrides, why = _closedloop_detector(
            "davis", _DAVIS, verdict, True, _SHOWN, k
        )
        assert "" == why
        # the overrides compose: the kept detector is the only one left, with that debounce
        node = compose(
            config_name="closedloop", overrides=[*_DAVIS, *overrides]
        ).closedloop
    assert [pick] == list(node.detectors)
    if k is not None:
        assert k == int(node.detectors[pick].debounce_k)
    return pick, overrides


def test_the_detector_of_the_deployed_debounce_is_picked() -> None:
    assert "polarity_lines_k3" == _pick("polarity_lines", 3)[0]
    assert "polarity_lines" == _pick("polarity_lines", 1)[0]
    assert "onset_k2" == _pick("onset", 2)[0]
    assert "onset_k3" == _pick("onset", 3)[0]


def test_a_debounce_the_scenario_lacks_is_added_under_its_own_name() -> None:
    pick, overrides = _pick("onset", 1)
    assert "onset_k1" == pick
    assert "+closedloop.detectors.onset_k1={run:onset,debounce_k:1}" in overrides


def test_without_a_bundle_the_mapping_decides() -> None:
    assert "onset_k2" == _pick("onset", None)[0]
