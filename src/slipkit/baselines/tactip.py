"""Import path kept for saved run folders; the family lives in slipkit.families.tactip."""

from slipkit.families.tactip.detector import PinMotionDetector  # noqa: F401
