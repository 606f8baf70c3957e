"""The FSR family: a force-sensing resistor under a fingertip (Gentile et al. 2020).

One folder, by role (``docs/extending.md``): :mod:`.physics` (the voltage divider and the
paper's calibration), :mod:`.scene` and :mod:`.effects` (simulated probe slides,
disturbances, wirings), the detectors :mod:`.touch_slip` (the paper's touch-and-slip rule)
and :mod:`.onset` (slip onset from the release's shape), the exporters (:mod:`.export`) and
the closed-loop scenario (:mod:`.scenario`). Training, deployment and comparison use the
generic stream-detection task, deployer and adapter. Its record, :data:`FAMILY`, lists them; they register when the stages load the
record's plug-in modules (``slipkit.families.load_plugins``); the runtime op ``press_sign`` stays in
``slipkit.runtime.preprocessing``.
"""

from slipkit.families import DETECTION_TASK, Family

_F = "slipkit.families.fsr."

FAMILY = Family(
    name="fsr",
    sensor="fsr",
    tasks=(DETECTION_TASK,),
    deploys=(DETECTION_TASK,),
    compares=(DETECTION_TASK,),
    exporters=(_F + "export.touch_slip", _F + "export.onset", "slipkit.export.generic"),
    scenes=("fsr_probe_slide", "fsr_probe_slide_hard"),
    comparisons=("fsr",),
    scenario="fsr",
    docs=("families/fsr.md",),
    detectors=(_F + "touch_slip", _F + "onset"),
    plugins={"scenarios": (_F + "scenario",), "effects": (_F + "effects",)},
)
