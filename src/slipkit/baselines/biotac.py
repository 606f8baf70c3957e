"""Import path kept for saved run folders; the family lives in slipkit.families.biotac."""

from slipkit.families.biotac.detectors import ForceDerivative, PressureVibration  # noqa: F401
