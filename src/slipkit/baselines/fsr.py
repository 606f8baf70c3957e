"""Import path kept for saved run folders; the family lives in slipkit.families.fsr."""

from slipkit.families.fsr.touch_slip import FSRTouchSlip, PolarityWarning  # noqa: F401
