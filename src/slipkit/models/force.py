"""Import path kept for saved run folders; the family lives in slipkit.families.biotac."""

from slipkit.families.biotac.force import (  # noqa: F401
    ForceMLP,
    LocalLinearRegressor,
    WeightedNormalsRegressor,
)
