"""Import path kept for saved run folders; the family lives in slipkit.families.sliptack."""

from slipkit.families.sliptack.accel import DropAcceleration  # noqa: F401
