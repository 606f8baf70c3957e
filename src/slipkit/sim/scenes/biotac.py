"""Import path kept for saved run folders; the family lives in slipkit.families.biotac."""

from slipkit.families.biotac.scene import BioTacForceProbe, BioTacLiftSlip  # noqa: F401
