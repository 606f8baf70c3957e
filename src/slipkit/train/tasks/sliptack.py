"""Import path kept for saved run folders; the family lives in slipkit.families.sliptack."""

from slipkit.families.sliptack.task import SlipTackAccel, SlipTackSpeed  # noqa: F401
