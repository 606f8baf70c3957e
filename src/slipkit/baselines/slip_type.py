"""Import path kept for saved run folders; the family lives in slipkit.families.biotac."""

from slipkit.families.biotac.slip_twist import SlipTwistClassifier  # noqa: F401
