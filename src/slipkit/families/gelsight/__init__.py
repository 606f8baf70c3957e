"""The GelSight family: marker tracking and import, pin-field features, streaming detectors and their report, their exporter, a simulated grasp scene and its sim-to-real check."""

from slipkit.families import DETECTION_TASK, Family

_F = "slipkit.families.gelsight."

FAMILY = Family(
    name="gelsight",
    sensor="gelsight",
    tasks=(DETECTION_TASK,),
    deploys=(DETECTION_TASK,),
    compares=(DETECTION_TASK,),
    exporters=(_F + "export",),
    scenes=("gelsight_grasp", "gelsight_grasp_setdown"),
    docs=("families/gelsight.md",),
    plugins={"effects": (_F + "effects",)},
)
