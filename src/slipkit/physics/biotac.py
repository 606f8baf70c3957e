"""Import path kept for the force models; the family lives in slipkit.families.biotac."""

from slipkit.families.biotac.physics import ELECTRODE_NORMALS  # noqa: F401
