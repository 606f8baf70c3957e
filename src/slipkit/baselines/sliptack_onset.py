"""Import path kept for saved run folders; the family lives in slipkit.families.sliptack."""

from slipkit.families.sliptack.onset import SlipTackOnset, SlipTackOnsetLogistic  # noqa: F401
