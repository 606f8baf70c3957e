"""Import path kept for saved run folders; the family lives in slipkit.families.biotac."""

from slipkit.families.biotac.direction_task import FingerDirection  # noqa: F401
