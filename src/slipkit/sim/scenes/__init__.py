"""Scene models, one module per sensor family; built from ``configs/scene/*.yaml``."""
