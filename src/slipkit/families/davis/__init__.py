"""The DAVIS family: an event camera watching the contact patch (Rigi et al. 2018).

One folder, by role (``docs/extending.md``): :mod:`.physics` (the contact patch),
:mod:`.scene` and :mod:`.effects` (simulated releases: contact-change events, vibration
incidents, background events), the detectors :mod:`.polarity` (the paper's
event-polarity rule) and :mod:`.onset` (a straight one-sided loss of contact), the learned
:mod:`.classifier` (per-frame polarity counts and areas), the release task (:mod:`.task`),
the exporters (:mod:`.export`), the deployers (:mod:`.deploy`), the comparison adapter
(:mod:`.adapter`) and the closed-loop scenario (:mod:`.scenario`). Its record, :data:`FAMILY`, lists them; they register when the stages load the
record's plug-in modules (``slipkit.families.load_plugins``); the runtime op ``davis_areas`` stays in
``slipkit.runtime.preprocessing``.
"""

from slipkit.families import Family

_F = "slipkit.families.davis."

FAMILY = Family(
    name="davis",
    sensor="davis",
    tasks=(_F + "task:DavisRelease",),
    deploys=(_F + "task:DavisRelease",),
    compares=(_F + "task:DavisRelease",),
    exporters=tuple(_F + "export." + m for m in ("polarity", "onset", "classifier")),
    scenes=("davis_release", "davis_release_hard"),
    comparisons=("davis",),
    scenario="davis",
    docs=("families/davis.md",),
    detectors=(_F + "polarity", _F + "onset"),
    plugins={
        "deployers": (_F + "deploy",),
        "adapters": (_F + "adapter",),
        "scenarios": (_F + "scenario",),
        "effects": (_F + "effects",),
        "tasks": (_F + "task",),
    },
)
