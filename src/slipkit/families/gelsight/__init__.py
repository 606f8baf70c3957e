"""The GelSight family: marker tracking, pin-motion features, streaming detectors."""

from slipkit.families import DETECTION_TASK, Family

_F = "slipkit.families.gelsight."

FAMILY = Family(
    name="gelsight",
    sensor="gelsight",
    tasks=(DETECTION_TASK,),
    deploys=(DETECTION_TASK,),
    compares=(DETECTION_TASK,),
    exporters=(_F + "export",),
    docs=("families/gelsight.md",),
)
