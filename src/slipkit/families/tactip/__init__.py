"""The TacTip family: a camera-tracked pin array whose pin velocities show slip.

One folder, by role: :mod:`.physics` (pin layout, Hertz contact), :mod:`.scene` and
:mod:`.effects` (the simulated gravity drop), :mod:`.features` (trials and datasets to
pin-velocity feature rows), the analytic pin-motion detector (:mod:`.detector`), the
frame tasks (:mod:`.task`, :mod:`.task_table`), the exporters (:mod:`.export`), the
deployer (:mod:`.deploy`), the comparison adapters (:mod:`.adapter`) and the closed-loop
scenario (:mod:`.scenario`). Its record, :data:`FAMILY`, lists them; they register when the stages load the
record's plug-in modules (``slipkit.families.load_plugins``).
The pin-velocity features and their graph stay generic (``slipkit.features.pins``,
``slipkit.export.pins``: other pin and marker sensors use them), as does the SVM
(``slipkit.models.svm``).
"""

from slipkit.families import DETECTION_TASK, Family

_F = "slipkit.families.tactip."

FAMILY = Family(
    name="tactip",
    sensor="tactip",
    tasks=(_F + "task:TacTipFrames", _F + "task_table:TacTipTable1", DETECTION_TASK),
    deploys=(_F + "task:TacTipFrames", DETECTION_TASK),
    compares=(_F + "task:TacTipFrames", DETECTION_TASK),
    exporters=(_F + "export.svm", _F + "export.detector"),
    scenes=("tactip_gravity_drop", "tactip_gravity_drop_hard"),
    comparisons=("tactip",),
    scenario="tactip",
    docs=("families/tactip.md",),
    detectors=(_F + "detector",),
    plugins={
        "deployers": (_F + "deploy",),
        "adapters": (_F + "adapter",),
        "scenarios": (_F + "scenario",),
        "effects": (_F + "effects",),
    },
)
