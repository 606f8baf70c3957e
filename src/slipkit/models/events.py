"""Import path kept for saved run folders; the family lives in slipkit.families.davis."""

from slipkit.families.davis.classifier import EventFrameClassifier  # noqa: F401
