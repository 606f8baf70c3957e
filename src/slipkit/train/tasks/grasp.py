"""Import path kept for saved run folders; the family lives in slipkit.families.biotac."""

from slipkit.families.biotac.grasp_task import GraspFeatures, GraspStability  # noqa: F401
