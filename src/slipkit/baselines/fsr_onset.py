"""Import path kept for saved run folders; the family lives in slipkit.families.fsr."""

from slipkit.families.fsr.onset import FSROnset, FSROnsetLogistic  # noqa: F401
