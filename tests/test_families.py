"""Every sensor family's record (slipkit.families) is complete: what it lists exists and is
registered where the stages look for it."""

from __future__ import annotations

from pathlib import Path

import pytest

from slipkit.families import FAMILIES, PLUGIN_MODULES, Family, load_plugins, resolve

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module", params=sorted(FAMILIES))
def family(request: pytest.FixtureRequest) -> Family:
    return FAMILIES[request.param]


def test_tasks_have_the_adapters_and_deployers_the_record_claims(
    family: Family,
) -> None:
    """Each listed task resolves; each task it deploys has a deployer, each task it compares
    an adapter (looked up as slipkit export and slipkit compare do, family folders'
    plug-ins loaded first)."""
    from slipkit.compare.adapters import _ADAPTERS
    from slipkit.export.deploy import _DEPLOYERS
    from slipkit.train.task import Task

    load_plugins("deployers")
    load_plugins("adapters")

    classes = {ref: resolve(ref) for ref in family.tasks}
    assert all(issubclass(c, Task) for c in classes.values())
    missing_deployers = [
        r for r in family.deploys if _DEPLOYERS.for_class(classes[r]) is None
    ]
    missing_adapters = [
        r for r in family.compares if _ADAPTERS.for_class(classes[r]) is None
    ]
    unlisted = [r for r in (*family.deploys, *family.compares) if r not in classes]
    assert ([], [], []) == (missing_deployers, missing_adapters, unlisted)


def test_exporter_modules_register_exporters(family: Family) -> None:
    """Each exporter module registers at least one exporter defined in it."""
    import slipkit.export  # noqa: F401  (imports and registers every exporter)
    from slipkit.export.registry import registered

    owners = {fn.__module__ for fn in registered().values()}
    assert [] == [m for m in family.exporters if resolve(m).__name__ not in owners]


def test_scenes_scenario_configs_and_docs_exist(family: Family) -> None:
    """Scene, comparison, closed-loop and deploy configs and doc pages exist; the scenario
    is registered under the family's scenario name."""
    from slipkit.closedloop.scenarios import get_scenario

    files = [
        *(f"configs/scene/{s}.yaml" for s in family.scenes),
        *(f"configs/comparison/{c}.yaml" for c in family.comparisons),
        f"configs/deploy/{family.sensor}.yaml",
        *(f"docs/{d}" for d in family.docs),
    ]
    if family.scenario is not None:
        files.append(f"configs/closedloop/{family.scenario}.yaml")
        assert get_scenario(family.scenario) is not None
    assert [] == [f for f in files if not (ROOT / f).is_file()]


def test_every_comparison_and_scenario_belongs_to_a_family() -> None:
    """No comparison or closed-loop config is left out of the records (own_sensor is the
    family-free comparison for a lab's own sensor)."""
    listed = {c for f in FAMILIES.values() for c in f.comparisons} | {"own_sensor"}
    scenarios = {f.scenario for f in FAMILIES.values()}
    comparisons = {p.stem for p in (ROOT / "configs/comparison").glob("*.yaml")}
    closedloop = {p.stem for p in (ROOT / "configs/closedloop").glob("*.yaml")}
    assert (set(), set()) == (comparisons - listed, closedloop - scenarios)


def test_plugin_modules_are_family_folders_and_register_when_loaded() -> None:
    """Every plug-in module lives in a family folder and loads; after loading, the stages'
    lookups find the SlipTack family's parts (its deployer, adapters, scenario, effects,
    analytic estimators)."""
    import importlib

    from slipkit.closedloop.scenarios import SCENARIOS, get_scenario
    from slipkit.compare.adapters import _ADAPTERS
    from slipkit.export.deploy import _DEPLOYERS
    from slipkit.sim.core import EFFECTS
    from slipkit.train.task import analytic_estimators

    modules = [m for kind in PLUGIN_MODULES.values() for m in kind]
    assert [] == [m for m in modules if not m.startswith("slipkit.families.")]
    for module in modules:
        importlib.import_module(module)
    st = importlib.import_module("slipkit.families.sliptack.task")
    speed = importlib.import_module("slipkit.families.sliptack.speed")
    assert _DEPLOYERS.for_class(st.SlipTackSpeed) is not None
    assert _ADAPTERS.for_class(st.SlipTackAccel) is not None
    assert {"stick_slip", "gross_deflection", "nib_harmonics"} <= set(EFFECTS)
    assert "sliptack" in SCENARIOS
    assert get_scenario("sliptack") is not None
    assert speed.StickSlipSpeed in analytic_estimators()


def test_fsr_folder_registers_its_effects_scenario_exporters_and_gate_margin() -> None:
    """The stages find the FSR family's parts through the plug-in modules: its effects,
    its closed-loop scenario, the exporters and runtime steps of its detectors and the
    parity check's gate margin of its touch-and-slip graph."""
    from slipkit.closedloop.scenarios import SCENARIOS, get_scenario
    from slipkit.export.detector_parity import _GATE_MARGINS
    from slipkit.export.registry import _RUNTIME_STEPS, exporter_for
    from slipkit.families import load_plugins
    from slipkit.sim.core import EFFECTS

    for kind in PLUGIN_MODULES:
        load_plugins(kind)
    from slipkit.families.fsr.onset import FSROnset, FSROnsetLogistic
    from slipkit.families.fsr.touch_slip import FSRTouchSlip

    assert {
        "fsr_slip_events",
        "fsr_disturbance",
        "fsr_impulse_disturbance",
        "fsr_touch",
        "fsr_polarity",
    } <= set(EFFECTS)
    assert "fsr" in SCENARIOS
    assert get_scenario("fsr") is not None
    for cls in (FSRTouchSlip, FSROnset, FSROnsetLogistic):
        assert exporter_for(cls()) is not None
        assert _RUNTIME_STEPS.for_class(cls) is not None
    assert _GATE_MARGINS.for_class(FSRTouchSlip) is not None


def test_family_detector_modules_train_in_the_detector_slot() -> None:
    """A family folder's detectors (``Family.detectors``) train in a comparison's detector
    slot and carry the analytic kind in the model card, as ``slipkit.baselines``'s do;
    learned models do not."""
    from slipkit.compare.commands import _is_analytic
    from slipkit.families import detector_module

    fsr = "slipkit.families.fsr."
    assert detector_module(fsr + "touch_slip")
    assert detector_module(fsr + "onset")
    assert detector_module("slipkit.families.biotac.detectors")
    assert detector_module("slipkit.families.sliptack.speed")
    assert not detector_module("slipkit.families.sliptack.spectral")
    assert not detector_module(fsr + "export.touch_slip")
    assert not detector_module("slipkit.models.window_detector")
    node = {"_target_": fsr + "touch_slip.FSRTouchSlip"}
    assert _is_analytic("fsr_roc", node, [])
    assert not _is_analytic("m", {"_target_": "slipkit.models.window.WindowMLP"}, [])


def test_each_family_folder_declares_its_own_record() -> None:
    """Every folder under slipkit/families/ is a family whose record lives in its own
    ``__init__.py`` (adding a family edits no shared module)."""
    import importlib

    folders = sorted(
        p.name
        for p in (ROOT / "src/slipkit/families").iterdir()
        if (p / "__init__.py").is_file() and not p.name.startswith("_")
    )
    assert folders == sorted(FAMILIES)
    for name in folders:
        module = importlib.import_module(f"slipkit.families.{name}")
        assert FAMILIES[name] is module.FAMILY


def _record(name: str, **parts: object) -> Family:
    return Family(
        name=name, sensor=name, tasks=(), deploys=(), compares=(), exporters=(), **parts
    )  # type: ignore[arg-type]


def test_a_family_package_registers_through_the_entry_point_group(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A lab's family shipped as its own package: an entry point of group
    ``slipkit.families`` naming a module with ``FAMILY`` joins the folders' records, and
    its plug-in modules join PLUGIN_MODULES."""
    import importlib.metadata
    import sys

    import slipkit.families as fam

    (tmp_path / "labfam.py").write_text(
        "from slipkit.families import Family\n"
        "FAMILY = Family(name='labfam', sensor='labfam', tasks=(), deploys=(),\n"
        "    compares=(), exporters=('labfam_export',),\n"
        "    plugins={'effects': ('labfam_effects',)})\n",
        encoding="utf-8",
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    ep = importlib.metadata.EntryPoint("labfam", "labfam", fam.ENTRY_POINT_GROUP)
    real = importlib.metadata.entry_points

    def entry_points(**kw: str) -> object:
        if kw.get("group") == fam.ENTRY_POINT_GROUP:
            return [ep]
        return real(**kw)

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    found = fam.discover()
    sys.modules.pop("labfam", None)
    assert set(FAMILIES) | {"labfam"} == set(found)
    modules = fam.plugin_modules(found)
    assert "labfam_export" in modules["exporters"]
    assert modules["effects"][-1] == "labfam_effects"
    # slipkit's own generic exporters are imported by slipkit.export, not as plug-ins
    assert not [m for m in modules["exporters"] if m.startswith("slipkit.export.")]


def test_a_second_record_of_one_name_or_a_folder_without_one_is_refused() -> None:
    from slipkit.errors import SlipkitError
    from slipkit.families import _record_of, discover, plugin_modules

    with pytest.raises(SlipkitError, match="'fsr' is already declared by here"):
        discover([("here", _record("fsr")), ("there", _record("fsr"))])
    with pytest.raises(
        SlipkitError, match=r"mylab\.fam: a sensor family declares FAMILY"
    ):
        _record_of(object(), "mylab.fam")
    bad = {"x": _record("x", plugins={"widgets": ("m",)})}
    with pytest.raises(SlipkitError, match="plugins kind 'widgets'"):
        plugin_modules(bad)
