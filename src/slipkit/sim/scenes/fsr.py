"""Import path kept for saved run folders; the family lives in slipkit.families.fsr."""

from slipkit.families.fsr.scene import FSRProbeSlide  # noqa: F401
