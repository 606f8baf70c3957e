"""Import path kept for saved run folders; the family lives in slipkit.families.biotac."""

from slipkit.families.biotac.electrode_energy import ElectrodeEnergyClassifier  # noqa: F401
