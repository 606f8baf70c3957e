"""Import path kept for saved run folders; the family lives in slipkit.families.davis."""

from slipkit.families.davis.onset import DavisOnset  # noqa: F401
