"""The SlipTack family: a whisker-like nib whose stick-slip frequency gives the slip speed.

One folder, by role (``docs/extending.md``): :mod:`.physics` (closed-form stick-slip),
:mod:`.scene` and :mod:`.effects` (simulated pulls and drops), the estimators
:mod:`.speed` (frequency -> speed), :mod:`.accel`, :mod:`.onset`, :mod:`.torsion` and
:mod:`.spectral`, the tasks (:mod:`.task`), the exporters (:mod:`.export`), the deployer
(:mod:`.deploy`), the comparison adapters (:mod:`.adapter`) and the closed-loop scenario
(:mod:`.scenario`). Its record, :data:`FAMILY`, lists them; they register when the stages load the
record's plug-in modules (``slipkit.families.load_plugins``); the
runtime op of the prepared spectrum stays in ``slipkit.runtime.ops.sliptack``.
"""

from slipkit.families import DETECTION_TASK, Family

_F = "slipkit.families.sliptack."

FAMILY = Family(
    name="sliptack",
    sensor="sliptack",
    tasks=(_F + "task:SlipTackSpeed", _F + "task:SlipTackAccel", DETECTION_TASK),
    deploys=(_F + "task:SlipTackSpeed", DETECTION_TASK),
    compares=(_F + "task:SlipTackSpeed", _F + "task:SlipTackAccel", DETECTION_TASK),
    exporters=tuple(
        _F + "export." + m
        for m in ("speed", "detector", "onset", "spectral", "torsion")
    ),
    scenes=("sliptack_pull", "sliptack_pull_hard", "sliptack_drop"),
    comparisons=("sliptack", "sliptack_slip"),
    scenario="sliptack",
    docs=("families/sliptack.md",),
    detectors=tuple(_F + m for m in ("speed", "accel", "onset", "torsion")),
    plugins={
        "deployers": (_F + "deploy",),
        "adapters": (_F + "adapter",),
        "scenarios": (_F + "scenario",),
        "effects": (_F + "effects",),
        "tasks": (_F + "task",),
    },
)
