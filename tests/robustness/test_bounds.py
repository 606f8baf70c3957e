"""Unbounded values are refused in one line naming them, before any work.

Closed-loop plant and scenario parameters have declared ranges (a typo such as
``substeps=1000000000`` or ``hold_s=1e9`` would hang or ask for terabytes),
``scenario=X`` takes dotted overrides as ``closedloop=X`` does.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from omegaconf import OmegaConf

from slipkit.cli import main
from slipkit.errors import SlipkitError
from slipkit.families.biotac import scenario as biotac
from slipkit.families.fsr import scenario as fsr
from slipkit.families.sliptack import scenario as sliptack
from slipkit.families.tactip import scenario as tactip


@pytest.fixture(autouse=True)
def _sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative outputs and internal-error logs land under tmp_path only."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SLIPKIT_LOG_DIR", str(tmp_path / "logs"))
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)


def cli(
    args: list[str], capsys: pytest.CaptureFixture[str]
) -> tuple[Any, str, list[str]]:
    """(exit status, stdout, non-blank stderr lines) of ``slipkit <args>``."""
    capsys.readouterr()
    try:
        main(args)
        code: Any = 0
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, [line for line in err.splitlines() if line.strip()]


def plant_of(family: str) -> dict[str, Any]:
    from slipkit import config_dir

    node = OmegaConf.load(config_dir() / "closedloop" / f"{family}.yaml")
    plant = OmegaConf.to_container(node.plant)
    assert isinstance(plant, dict)
    return {str(k): v for k, v in plant.items()}


CHECKS = {
    "fsr": fsr.check_plant,
    "biotac": biotac.check_plant,
    "tactip": tactip.check_scenario,
    "sliptack": sliptack.check_plant,
}


@pytest.mark.parametrize("family", sorted(CHECKS))
def test_the_shipped_plants_are_within_their_ranges(family: str) -> None:
    """Every configs/closedloop/<family>.yaml plant passes its family's declared ranges."""
    assert CHECKS[family](plant_of(family)) is None


@pytest.mark.parametrize(
    ("family", "key", "value", "message"),
    [
        (
            "fsr",
            "substeps",
            1_000_000_000,
            "closedloop.plant.substeps=1000000000: expected a whole number in [1, 64]",
        ),
        (
            "fsr",
            "hold_s",
            1e9,
            "closedloop.plant.hold_s=1000000000.0: expected a number in [0, 10] s",
        ),
        (
            "fsr",
            "contacts",
            0,
            "closedloop.plant.contacts=0: expected a whole number in [1, 5]",
        ),
        (
            "fsr",
            "latency_s",
            1e300,
            "closedloop.plant.latency_s=1e+300: expected a number in [0, 0.5] s",
        ),
        (
            "fsr",
            "latency_s",
            -1,
            "closedloop.plant.latency_s=-1: expected a number in [0, 0.5] s",
        ),
        (
            "fsr",
            "mass_kg",
            [0.4, 0.2],
            "closedloop.plant.mass_kg=[0.4, 0.2]: expected a number or [lo, hi] within (0, 20] kg",
        ),
        (
            "biotac",
            "hold_s",
            1e9,
            "closedloop.plant.hold_s=1000000000.0: expected a number in [0, 10] s",
        ),
        (
            "biotac",
            "control_hz",
            0,
            "closedloop.plant.control_hz=0: expected a number in (0, 10000] Hz",
        ),
        (
            "tactip",
            "latency_s",
            1e300,
            "closedloop.plant.latency_s=1e+300: expected a number in [0, 0.5] s",
        ),
        (
            "tactip",
            "substeps",
            10**9,
            "closedloop.plant.substeps=1000000000: expected a whole number in [1, 64]",
        ),
        (
            "sliptack",
            "substeps",
            10**9,
            "closedloop.plant.substeps=1000000000: expected a whole number in [1, 64]",
        ),
        (
            "sliptack",
            "post_s",
            1e9,
            "closedloop.plant.post_s=1000000000.0: expected a number in (0, 10] s",
        ),
    ],
)
def test_a_plant_parameter_out_of_range_is_refused(
    family: str, key: str, value: Any, message: str
) -> None:
    """A plant parameter outside its declared range is one SlipkitError naming it and the range."""
    with pytest.raises(SlipkitError) as refused:
        CHECKS[family]({**plant_of(family), key: value})
    assert message == str(refused.value)


@pytest.mark.parametrize(
    ("scenario", "grid", "node", "message"),
    [
        (
            fsr.FSRScenario,
            "conditions",
            {"lo": 0.25, "hi": 1.0, "n": 10**9},
            "closedloop.conditions.n=1000000000: expected a whole number in [1, 100]",
        ),
        (
            biotac.BioTacScenario,
            "conditions",
            {"lo": 0.0, "hi": 1.0, "n": 3},
            "closedloop.conditions.lo=0.0: expected a number in (0, 10] s",
        ),
        (
            tactip.TacTipScenario,
            "speeds",
            {"lo": 20.0, "hi": 0.1, "n": 3},
            "closedloop.speeds.lo=20: expected <= closedloop.speeds.hi (0.1)",
        ),
        (
            sliptack.SlipTackScenario,
            "pull_speeds",
            {"lo": 10.0, "hi": 1e9, "n": 3},
            "closedloop.pull_speeds.hi=1000000000.0: expected a number in (0, 1000] mm/s",
        ),
    ],
)
def test_a_conditions_grid_out_of_range_is_refused(
    scenario: Any, grid: str, node: dict[str, Any], message: str
) -> None:
    """A conditions grid with too many points or a value out of range is one SlipkitError naming it."""
    with pytest.raises(SlipkitError) as refused:
        scenario().conditions(OmegaConf.create({grid: node, "drop": True}))
    assert message == str(refused.value)


def test_scenario_takes_the_dotted_overrides_of_its_own_file(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """scenario=fsr applies closedloop.* overrides to fsr.yaml, keys only fsr.yaml has included."""
    code, out, err = cli(
        [
            "closedloop",
            "scenario=fsr",
            "closedloop.plant.latency_s=0.05",
            "closedloop.plant.load_factor=[1.6,2.0]",
            "--cfg",
            "job",
        ],
        capsys,
    )
    plant = OmegaConf.create(out).closedloop
    assert (0, [], "fsr", 0.05, [1.6, 2.0]) == (
        code,
        err,
        plant.name,
        plant.plant.latency_s,
        list(plant.plant.load_factor),
    )


def test_scenario_with_a_bad_dotted_override_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """scenario=fsr closedloop.plant.latency_s=-1 is one line naming it, exit 2, nothing written."""
    code, _, err = cli(
        [
            "closedloop",
            "scenario=fsr",
            "closedloop.plant.latency_s=-1",
            f"out={tmp_path / 'cl'}",
        ],
        capsys,
    )
    assert (
        2,
        [
            "slipkit closedloop: error: closedloop.plant.latency_s=-1: expected a number in [0, 0.5] s"
        ],
        False,
    ) == (code, err, (tmp_path / "cl").exists())


def test_a_core_list_beyond_any_machine_is_refused() -> None:
    """slipkit-run --cpus 0-999999999 is one OptionError naming --cpus, not a set of 1e9 cores."""
    from slipkit.runtime.errors import OptionError
    from slipkit.runtime.realtime import parse_cpus

    with pytest.raises(OptionError) as refused:
        parse_cpus("0-999999999")
    assert (
        "--cpus: core numbers must be below 4096; got '0-999999999'",
        (0, 4095),
    ) == (str(refused.value), parse_cpus("0,4095"))


@pytest.mark.parametrize("rate", ["1e9", "1e-9"])
def test_a_scene_rate_out_of_range_is_refused(
    rate: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """slipkit simulate at 1e9 Hz or 1e-9 Hz is one line naming the rate and its range, exit 2."""
    code, _, err = cli(
        ["simulate", f"scene.model.rate_hz={rate}", f"out={tmp_path / 'd'}"], capsys
    )
    assert (
        2,
        [
            f"slipkit simulate: error: scene.model.rate_hz={float(rate)}: expected a number "
            "in [1, 100000] Hz"
        ],
        False,
    ) == (code, err, (tmp_path / "d").exists())


def test_a_scene_with_no_samples_is_refused() -> None:
    """A scene whose rate and duration give no sample (direct API, 0.01 Hz) raises a SimulationError naming the stream."""
    from hydra import compose, initialize_config_dir

    from slipkit import config_dir
    from slipkit.sim.commands import build_scene
    from slipkit.sim.core import SimulationError

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose("simulate", ["scene=fsr_probe_slide", "scene.model.rate_hz=0.01"])
    with pytest.raises(SimulationError) as refused:
        build_scene(cfg.scene).simulate(2, 0)
    assert (
        "scene 'fsr_probe_slide': stream 'fsr' has no samples in any of the 2 trials "
        "(is scene.model's rate or duration too small?)"
    ) == str(refused.value)


@pytest.mark.parametrize(
    ("override", "line"),
    [
        (
            "closedloop.oracle_delays_ms=[-5]",
            "closedloop.oracle_delays_ms[0]=-5: expected a number in [0, 1000] ms",
        ),
        (
            "closedloop.oracle_delays_ms=abc",
            "closedloop.oracle_delays_ms=abc: expected a list of delays in ms, e.g. [10, 25]",
        ),
        (
            "closedloop.plant=5",
            "closedloop.plant=5: expected a mapping of plant parameters",
        ),
        (
            "closedloop.trials_per_speed=0",
            "closedloop.trials_per_speed=0: expected a whole number in [1, 1000]",
        ),
        (
            "trials_per_speed=100000000",
            "trials_per_speed=100000000: expected a whole number in [1, 1000] or null",
        ),
        (
            "closedloop.scene=nope",
            "closedloop.scene=nope: In 'train': Could not find 'scene/nope'; available: ",
        ),
    ],
)
def test_a_bad_closed_loop_option_is_one_line(
    override: str, line: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A closed-loop option out of range or of the wrong kind is one line naming it, exit 2, nothing written."""
    code, _, err = cli(["closedloop", override, f"out={tmp_path / 'cl'}"], capsys)
    assert (2, 1, True, False) == (
        code,
        len(err),
        err[0].startswith(f"slipkit closedloop: error: {line}"),
        (tmp_path / "cl").exists(),
    ), err


@pytest.mark.parametrize(
    ("override", "numbers"),
    [
        ("scene.model.duration_s=1e9", "3e+13"),
        ("scene.model.rate_hz=100000", "1.7e+08"),
    ],
)
def test_a_trial_too_large_to_hold_is_refused(
    override: str, numbers: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A TacTip trial of 1e9 s, or at 100 kHz, is one line with its size, exit 2, before simulating."""
    code, _, err = cli(
        ["simulate", "scene=tactip_gravity_drop", override, f"out={tmp_path / 'd'}"],
        capsys,
    )
    assert (2, 1, True, False) == (
        code,
        len(err),
        err[0].startswith(
            "slipkit simulate: error: scene 'tactip_gravity_drop': stream 'pins' would "
            f"hold about {numbers} numbers per trial"
        ),
        (tmp_path / "d").exists(),
    ), err


def test_scenario_and_closedloop_naming_two_scenarios_is_refused(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """scenario=fsr closedloop=tactip is one line naming both, not a silent pick of one."""
    code, _, err = cli(
        ["closedloop", "scenario=fsr", "closedloop=tactip", "--cfg", "job"], capsys
    )
    assert (
        2,
        [
            "slipkit closedloop: error: scenario=fsr and closedloop=tactip name different "
            "options; give one of them"
        ],
    ) == (code, err)


def test_a_composed_config_with_overrides_of_another_scenario_is_refused() -> None:
    """A config composed with scenario=fsr and tactip's closedloop.* overrides is refused, not run without them."""
    from hydra import compose, initialize_config_dir

    from slipkit import config_dir
    from slipkit.closedloop.commands import load_scenario

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose("closedloop", ["scenario=fsr", "closedloop.plant.latency_s=0.05"])
        with pytest.raises(SlipkitError) as refused:
            load_scenario(cfg)
        plain = load_scenario(compose("closedloop", ["scenario=fsr"]))
    assert (
        "scenario=fsr: the closedloop.* overrides apply to scenario tactip; give "
        "closedloop=fsr with them",
        "fsr",
    ) == (str(refused.value), plain.name)
