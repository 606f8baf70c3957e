"""Import path kept for saved run folders; the family lives in slipkit.families.sliptack."""

from slipkit.families.sliptack.export.detector import SpeedSlipDetector  # noqa: F401
